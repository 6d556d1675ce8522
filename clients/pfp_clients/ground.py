"""The DEM a client takes with ``--terrain DEM``: read once, within the planner's bounds, sampled in lat/lon.

``pfp map``, ``pfp tak`` and ``pfp report`` each read the DEM themselves, with
the planner's own reader (``pfp_service.terrain.dem.read_dem``: the same
drivers, the same ``dem_side_cells``/``dem_block_cells``/``dem_cells`` bounds,
the same one-line refusals naming the file).  The whole DEM is read, so a DEM
of more than ``dem_cells`` cells is refused with "crop it smaller": a client
cannot know which part of it the mission will use.

Heights are the DEM's values as they are: metres above the DEM's own vertical
datum, which for SRTM, Copernicus and DTED is the geoid (orthometric heights,
EGM96 or EGM2008), not the WGS-84 ellipsoid (docs/terrain.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pfp_service.geo import Origin
from pfp_service.terrain.dem import Dem, check, read_dem, to_dem_crs
from pfp_service.terrain.grid import bilinear

__all__ = ["Ground", "load_ground"]


@dataclass(frozen=True)
class Ground:
    """A DEM read whole: its cells, and its box in latitude and longitude (south, west, north, east)."""

    dem: Dem
    bounds_latlon: tuple[float, float, float, float]

    @property
    def path(self) -> str:
        return self.dem.path

    def centre(self) -> Origin:
        """The DEM's centre, at its ground height there (the origin when nothing else gives one)."""
        s, w, n, e = self.bounds_latlon
        lat, lon = (s + n) / 2.0, (w + e) / 2.0
        z = float(self.elevation(np.array([lat]), np.array([lon]))[0])
        return Origin(lat=lat, lon=lon, alt=z if np.isfinite(z) else 0.0)

    def cells(self, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The fractional ``(row, col)`` of each point, cell centres at whole numbers."""
        x, y = to_dem_crs(self.dem.crs, np.asarray(lat, dtype=float), np.asarray(lon, dtype=float))
        col, row = ~self.dem.transform @ (x, y)
        return np.asarray(row, dtype=float) - 0.5, np.asarray(col, dtype=float) - 0.5

    def elevation(self, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
        """The ground at each point, metres, interpolated bilinearly; NaN off the DEM or next to no-data."""
        row, col = self.cells(lat, lon)
        return bilinear(self.dem.elevation, col, row)


def load_ground(path: str) -> Ground:
    """Read the DEM at ``path`` whole.

    Raises:
        InputError: path ``path``: not a DEM, no CRS that can be placed, or more cells than a bound.
    """
    from rasterio.transform import array_bounds
    from rasterio.warp import transform_bounds

    check(path)  # the header's bounds first, reading no cell
    dem = read_dem(path)
    rows, cols = dem.elevation.shape
    left, bottom, right, top = array_bounds(rows, cols, dem.transform)  # in the DEM's CRS
    w, s, e, n = transform_bounds(dem.crs, "EPSG:4326", left, bottom, right, top, densify_pts=21)
    return Ground(dem, (float(s), float(w), float(n), float(e)))
