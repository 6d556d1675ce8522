"""Rendering results for people: text summaries (``text``) and PNG plots (``plots`` of a plan, ``tracks`` of several units; matplotlib).

``plots`` draws fields, zones and paths; ``geo_axes`` its lat/lon axes; ``terrain_layers``
the ground under a plan over terrain (hillshade, contours, where each threat sees).

Nothing here plans or talks to the network: it takes plan results, threats
and tracks and returns text or writes one image.  matplotlib is imported
only when a plot is drawn, so ``summary`` works on a plain install.
"""

from __future__ import annotations

from pfp_service.render.plots import check_png_path, extent, plot_plan
from pfp_service.render.text import summary
from pfp_service.render.tracks import plot_tracks

__all__ = ["check_png_path", "extent", "plot_plan", "plot_tracks", "summary"]
