"""Terrain: a DEM read within bounds, placed on the planner's plane, sampled smoothly, and seen over.

    dem.py       the one module that opens rasters (rasterio/GDAL): checks, crops, fills holes, writes masks
    grid.py      the DEM resampled onto the planner's local plane; bilinear elevation, exact gradient, slope
    viewshed.py  the lowest visible height per cell: a compiled sweep (Wang 2000) and an exact ray (R3)
    sight.py     a viewshed on a DEM's own grid for an observer in latitude and longitude
    threat_sight.py  per threat, its window of lowest visible heights within its reach (core.visibility)
    barriers.py  cells steeper than a unit's limit, or unknown, as keep-out zones
    planning.py  a DEM placed under a scenario for pfp plan, and a path measured over it

``viewshed`` and ``grid.TerrainGrid`` do no I/O: arrays in, arrays out.
docs/terrain.md says what no-data and the DEM's edges mean.
"""

from __future__ import annotations

import importlib
from typing import Any

# loaded on first use: a command that reads (or refuses) a raster never imports the compiled
# viewshed (numba, about 100 MB, and a compile on a fresh checkout), so a hostile file is refused
# within the bounds table's memory (tests/proc/test_light_commands.py)
_WHERE = {
    "Dem": "dem",
    "DemInfo": "dem",
    "info": "dem",
    "read_dem": "dem",
    "TerrainGrid": "grid",
    "place": "grid",
    "exact_lowest_visible_height": "viewshed",
    "lowest_visible_height": "viewshed",
    "visible": "viewshed",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
