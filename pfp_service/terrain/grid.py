"""Terrain in the planner's metres: a regular grid east and north of the mission origin, sampled smoothly.

``place`` puts a DEM on the planner's own plane (``geo.Origin``: the local
tangent plane at the origin, x east, y north) without a second projection:
each grid point's local metres go to WGS-84 through ``Origin.to_geodetic_many``
(the exact inverse of the planner's ``to_local``), then to the DEM's CRS
through PROJ, then to a fractional cell of the DEM, where the elevation is
interpolated bilinearly.  The grid is therefore the DEM resampled once, at
the resolution asked for, on exactly the plane the planner steps on; a
UTM DEM's grid convergence and scale, and a geographic DEM's unequal degrees,
are all absorbed there.

``TerrainGrid`` samples that grid between its points: bilinear elevation,
and the exact gradient of that bilinear surface (piecewise: on a cell edge the
gradient is the cell's to the east or north), vectorised over arrays of
points.  Outside the grid, or in a cell with an unknown corner, a sample is
NaN: unknown ground (docs/terrain.md says what each consumer makes of it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pfp_service.bounds import LIMITS
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.terrain.dem import Dem, read_dem, to_dem_crs

__all__ = ["TerrainGrid", "bilinear", "latlon_box", "load", "place"]


@dataclass(frozen=True)
class TerrainGrid:
    """Elevations ``z[j, i]`` at ``(x0_m + i * cell_m, y0_m + j * cell_m)``: row ``j`` runs north."""

    x0_m: float
    y0_m: float
    cell_m: float
    z: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.z.shape[0]), int(self.z.shape[1])

    def _locate(self, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, ...]:
        fx = (np.asarray(x_m, dtype=float) - self.x0_m) / self.cell_m
        fy = (np.asarray(y_m, dtype=float) - self.y0_m) / self.cell_m
        ny, nx = self.shape
        inside = (fx >= 0) & (fx <= nx - 1) & (fy >= 0) & (fy <= ny - 1)
        # the last row or column uses the cell before it, at fraction 1
        i = np.clip(np.floor(np.where(inside, fx, 0.0)), 0, max(nx - 2, 0)).astype(np.intp)
        j = np.clip(np.floor(np.where(inside, fy, 0.0)), 0, max(ny - 2, 0)).astype(np.intp)
        tx, ty = np.where(inside, fx - i, 0.0), np.where(inside, fy - j, 0.0)
        z00, z10 = self.z[j, i], self.z[j, i + 1]
        z01, z11 = self.z[j + 1, i], self.z[j + 1, i + 1]
        return inside, tx, ty, z00, z10, z01, z11

    def elevation(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Bilinear ground height at each point, metres; NaN outside the grid or next to unknown ground."""
        inside, tx, ty, z00, z10, z01, z11 = self._locate(x_m, y_m)
        z = (1 - ty) * ((1 - tx) * z00 + tx * z10) + ty * ((1 - tx) * z01 + tx * z11)
        return np.where(inside, z, np.nan)

    def gradient(self, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(dz/dx, dz/dy)`` of the bilinear surface at each point (metres per metre); NaN as ``elevation``."""
        inside, tx, ty, z00, z10, z01, z11 = self._locate(x_m, y_m)
        gx = ((1 - ty) * (z10 - z00) + ty * (z11 - z01)) / self.cell_m
        gy = ((1 - tx) * (z01 - z00) + tx * (z11 - z10)) / self.cell_m
        return np.where(inside, gx, np.nan), np.where(inside, gy, np.nan)

    def slope_deg(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """The steepest slope of the ground at each point, degrees from level."""
        gx, gy = self.gradient(x_m, y_m)
        return np.degrees(np.arctan(np.hypot(gx, gy)))

    def cell_of(self, x_m: float, y_m: float) -> tuple[int, int]:
        """The ``(row, col)`` of the grid point nearest ``(x_m, y_m)``, or ``ValueError`` off the grid."""
        j = round((y_m - self.y0_m) / self.cell_m)
        i = round((x_m - self.x0_m) / self.cell_m)
        if not (0 <= j < self.shape[0] and 0 <= i < self.shape[1]):
            raise ValueError(f"({x_m:.1f}, {y_m:.1f}) m is off the terrain grid")
        return j, i


def bilinear(z: np.ndarray, col: np.ndarray, row: np.ndarray) -> np.ndarray:
    """``z`` interpolated at fractional cell centres ``(col, row)``; NaN outside or next to a NaN."""
    nr, nc = z.shape
    inside = (col >= 0) & (col <= nc - 1) & (row >= 0) & (row <= nr - 1)
    c = np.where(inside, col, 0.0)
    r = np.where(inside, row, 0.0)
    i = np.clip(np.floor(c), 0, max(nc - 2, 0)).astype(np.intp)
    j = np.clip(np.floor(r), 0, max(nr - 2, 0)).astype(np.intp)
    tc, tr = c - i, r - j
    i1, j1 = np.minimum(i + 1, nc - 1), np.minimum(j + 1, nr - 1)
    top = (1 - tc) * z[j, i] + tc * z[j, i1]
    bottom = (1 - tc) * z[j1, i] + tc * z[j1, i1]
    return np.where(inside, (1 - tr) * top + tr * bottom, np.nan)


def place(
    dem: Dem, origin: Origin, bounds_m: tuple[float, float, float, float], cell_m: float
) -> TerrainGrid:
    """The DEM resampled onto the planner's plane over ``bounds_m`` (xmin, ymin, xmax, ymax), every ``cell_m``.

    Raises:
        InputError: path the DEM's; more grid points than ``dem_cells``, or a cell size not positive.
    """
    xmin, ymin, xmax, ymax = bounds_m
    if not (cell_m > 0 and math.isfinite(cell_m)):
        raise InputError(dem.path, f"a terrain cell must be positive metres, not {cell_m}")
    nx = math.floor((xmax - xmin) / cell_m + 1e-9) + 1
    ny = math.floor((ymax - ymin) / cell_m + 1e-9) + 1
    if nx * ny > LIMITS["dem_cells"].value:
        raise InputError(
            dem.path,
            f"{nx:,} x {ny:,} terrain points at {cell_m:g} m, more than {LIMITS['dem_cells'].value:,} (dem_cells)",
        )
    xs = xmin + cell_m * np.arange(nx)
    ys = ymin + cell_m * np.arange(ny)
    z = np.empty((ny, nx))
    inverse = ~dem.transform
    for j0 in range(0, ny, 256):  # a band of rows at a time: the intermediate arrays stay small
        gx, gy = np.meshgrid(xs, ys[j0 : j0 + 256])
        ll = origin.to_geodetic_many(np.column_stack([gx.ravel(), gy.ravel()]))
        cx, cy = to_dem_crs(dem.crs, ll[:, 0], ll[:, 1])
        col, row = inverse @ (cx, cy)
        # the affine gives cell corners; elevations sit at cell centres
        z[j0 : j0 + 256] = bilinear(dem.elevation, np.asarray(col) - 0.5, np.asarray(row) - 0.5).reshape(
            gx.shape
        )
    return TerrainGrid(float(xmin), float(ymin), float(cell_m), z)


def latlon_box(
    origin: Origin, bounds_m: tuple[float, float, float, float]
) -> tuple[float, float, float, float]:
    """(south, west, north, east) degrees enclosing ``bounds_m`` (xmin, ymin, xmax, ymax) of the plane.

    Corners and edge midpoints are taken: the plane's straight edges are slightly curved in degrees.
    """
    xmin, ymin, xmax, ymax = bounds_m
    xs, ys = (xmin, (xmin + xmax) / 2, xmax), (ymin, (ymin + ymax) / 2, ymax)
    ll = origin.to_geodetic_many(np.array([[x, y] for x in xs for y in ys]))
    return float(ll[:, 0].min()), float(ll[:, 1].min()), float(ll[:, 0].max()), float(ll[:, 1].max())


def load(
    path: str, origin: Origin, bounds_m: tuple[float, float, float, float], cell_m: float
) -> TerrainGrid:
    """Read the DEM's window under ``bounds_m`` (planner metres) and place it there (``read_dem`` + ``place``).

    Raises:
        InputError: as ``read_dem`` (not a DEM, not covering the area, past a bound) and ``place``.
    """
    return place(read_dem(path, latlon_box(origin, bounds_m)), origin, bounds_m, cell_m)
