"""A viewshed on a DEM's own grid, for an observer given in latitude and longitude.

``pfp terrain viewshed`` answers on the DEM's grid (a GeoTIFF a GIS overlays
on the DEM), so the sweep runs on the DEM's cells as they are, not on a
resampled grid.  Distances between cells are measured on the planner's plane
centred on the observer (``geo.Origin``): the cell's width and height in
metres at the observer (``cell_metres``) turn index offsets into metres.  A
UTM grid is a conformal map (a turn and a scale of 1 +- 0.0004), and a
geographic grid's metres per degree of longitude change by
``tan(lat) * d / R`` over a distance ``d`` (0.06 % at 5 km and 36 N), so
taking them at the observer moves no cell by more than a few metres at 5 km
and changes no sight line's slope by more than that fraction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.terrain.dem import Dem, read_dem, to_dem_crs
from pfp_service.terrain.viewshed import lowest_visible_height

__all__ = ["Sight", "cell_metres", "observe"]


@dataclass(frozen=True)
class Sight:
    """A viewshed on a DEM window: the lowest visible height per cell (NaN beyond the radius)."""

    dem: Dem
    observer_rc: tuple[int, int]
    dx_m: float
    dy_m: float
    lowest_m: np.ndarray


def cell_metres(dem: Dem, row: int, col: int) -> tuple[float, float]:
    """A cell's width (along a row) and height (along a column) in metres at ``(row, col)``."""
    from rasterio.warp import transform as warp

    pts = [dem.transform @ (col + 0.5 + a, row + 0.5 + b) for a, b in ((0, 0), (1, 0), (0, 1))]
    lon, lat = warp(dem.crs, "EPSG:4326", [p[0] for p in pts], [p[1] for p in pts])
    xy = Origin(lat=lat[0], lon=lon[0]).to_local_many(np.column_stack([lat, lon]))
    return float(np.hypot(*(xy[1] - xy[0]))), float(np.hypot(*(xy[2] - xy[0])))


def observe(
    path: str,
    lat: float,
    lon: float,
    observer_height_m: float,
    radius_m: float | None,
    curvature: float,
    flag: str = "--observer",
) -> Sight:
    """The viewshed of an observer at ``(lat, lon)``, ``observer_height_m`` above the DEM's ground.

    With ``radius_m`` only the DEM's cells within the square around it are read.

    Raises:
        InputError: path ``path`` for a DEM that cannot be read or placed; ``flag`` for an observer
            outside the DEM or on unknown ground.
    """
    area = None
    if radius_m is not None:
        # the square around the observer, its corners and edge midpoints on WGS-84 (read_dem takes their box)
        o = Origin(lat=lat, lon=lon)
        r = radius_m * 1.001
        ring = np.array([[a * r, b * r] for a in (-1, 0, 1) for b in (-1, 0, 1)])
        ll = o.to_geodetic_many(ring)
        area = (float(ll[:, 0].min()), float(ll[:, 1].min()), float(ll[:, 0].max()), float(ll[:, 1].max()))
    dem = read_dem(path, area, clip=True)
    x, y = to_dem_crs(dem.crs, np.array([lat]), np.array([lon]))
    col_f, row_f = ~dem.transform @ (float(x[0]), float(y[0]))
    row, col = math.floor(row_f), math.floor(col_f)
    rows, cols = dem.elevation.shape
    if not (0 <= row < rows and 0 <= col < cols):
        raise InputError(flag, f"{lat:.6f},{lon:.6f} is outside the DEM {path}")
    if not math.isfinite(dem.elevation[row, col]):
        raise InputError(flag, f"{lat:.6f},{lon:.6f} stands on no-data in {path}: its ground is unknown")
    dx, dy = cell_metres(dem, row, col)
    reach = radius_m if radius_m is not None else math.inf
    lowest = lowest_visible_height(dem.elevation, (row, col), observer_height_m, reach, dx, dy, curvature)
    return Sight(dem, (row, col), dx, dy, lowest)
