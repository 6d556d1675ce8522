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

from pfp_service.terrain.dem import Dem, DemInfo, info, read_dem
from pfp_service.terrain.grid import TerrainGrid, place
from pfp_service.terrain.viewshed import exact_lowest_visible_height, lowest_visible_height, visible

__all__ = [
    "Dem",
    "DemInfo",
    "TerrainGrid",
    "exact_lowest_visible_height",
    "info",
    "lowest_visible_height",
    "place",
    "read_dem",
    "visible",
]
