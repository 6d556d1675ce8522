"""``pfp map``: the operator's live map of a mission, a Zenoh client serving one web page.

geometry   threat outlines (zone and core) as polygons, sans-I/O
model      what the map knows and what changed since a page last heard (sans-I/O)
feed       the Zenoh side: thin callbacks, a coalescing inbox, queries and edits
server     the web side: the page, its WebSocket of deltas with flow control, the API
embed      the map on its own thread inside another program (``pfp demo --map``)
static/    the page, and Leaflet 1.9.4 vendored with its licence
"""
