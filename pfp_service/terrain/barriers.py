"""Ground a unit cannot cross, as keep-out zones: cells steeper than its limit, and unknown ground.

A grid cell of a ``TerrainGrid`` is a barrier when its bilinear surface is
steeper than the limit anywhere in it.  Each component of the bilinear
gradient is linear across the cell, so its norm is convex and greatest at a
corner: the cell is tested at its four corners, and a cell that passes has no
point steeper than the limit.  A cell with an unknown corner is a barrier
too (ground the planner cannot judge).

The barrier cells become ``core.zones.Zone`` polygons, GDAL's polygonize
(``rasterio.features.shapes``) run per tile of ``TILE`` x ``TILE`` cells so
that no zone passes ``MAX_VERTICES`` or ``MAX_RINGS``.  Every path that
respects keep-out zones then respects slope: the step rule cuts a step short
at one, the route searches (``global``, A*, ``--planner optimal``) never
cross one, and a goal behind them is ``trapped`` with a reason naming the
zone, whose id says why (``slope>30deg#12``, ``unknown-ground#3``).
"""

from __future__ import annotations

import math

import numpy as np

from pfp_service.core.zones import Zone
from pfp_service.terrain.grid import TerrainGrid

__all__ = ["TILE", "barrier_cells", "barrier_zones"]

TILE = 16  # at most 7 x 7 holes (< MAX_RINGS) and about 600 vertices (< MAX_VERTICES) a zone


def barrier_cells(grid: TerrainGrid, max_slope_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """``(steep, unknown)``: boolean ``(ny - 1, nx - 1)`` masks of the cells a unit cannot enter."""
    z = grid.z
    c = grid.cell_m
    z00, z10, z01, z11 = z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]
    south, north = (z10 - z00) / c, (z11 - z01) / c  # d/dx along the cell's south and north edges
    west, east = (z01 - z00) / c, (z11 - z10) / c  # d/dy along its west and east edges
    limit = math.tan(math.radians(max_slope_deg))
    with np.errstate(invalid="ignore"):
        worst = np.maximum.reduce(
            [np.hypot(south, west), np.hypot(south, east), np.hypot(north, west), np.hypot(north, east)]
        )
        unknown = ~np.isfinite(worst)
        steep = ~unknown & (worst > limit)
    return steep, unknown


def barrier_zones(grid: TerrainGrid, max_slope_deg: float) -> list[Zone]:
    """The barrier cells as keep-out zones (ids ``slope>{limit}deg#n`` and ``unknown-ground#n``)."""
    from affine import Affine
    from rasterio.features import shapes

    steep, unknown = barrier_cells(grid, max_slope_deg)
    out: list[Zone] = []
    for mask, name in ((steep, f"slope>{max_slope_deg:g}deg"), (unknown, "unknown-ground")):
        if not mask.any():
            continue
        ny, nx = mask.shape
        for k0 in range(0, ny, TILE):
            for i0 in range(0, nx, TILE):
                tile = mask[k0 : k0 + TILE, i0 : i0 + TILE]
                if not tile.any():
                    continue
                # cell (k, i) spans x0 + i c .. x0 + (i + 1) c and y0 + k c .. y0 + (k + 1) c
                at = Affine(
                    grid.cell_m,
                    0.0,
                    grid.x0_m + i0 * grid.cell_m,
                    0.0,
                    grid.cell_m,
                    grid.y0_m + k0 * grid.cell_m,
                )
                for geom, _ in shapes(tile.astype(np.uint8), mask=tile, connectivity=4, transform=at):
                    rings = geom["coordinates"]
                    out.append(Zone.polygon(f"{name}#{len(out) + 1}", rings[0], rings[1:]))
    return out
