"""Mission records: every key of a mission in an MCAP file, played back, and summed up after the action.

* ``mcapfile``: the file's layout (one channel per key, the wire's JSON
  schemas, deletions and liveliness on their own channels, Foxglove
  ``LocationFix`` topics when the origin is known), its writer and its reader;
* ``recorder``: ``pfp record`` -- a Zenoh subscriber on ``mumt/{m}/**`` that
  decodes nothing and hands each sample to one writer thread;
* ``replay``: ``pfp replay`` -- the recorded inputs (states, goals, threats,
  zones) put again on a mission, on the recorded clock, and the directions a
  fresh planner gives compared with the recorded ones;
* ``report``: ``pfp report`` -- per unit its track, time, exposure, replans
  and their causes, as a table, a plot and (with an origin) GeoJSON.
"""
