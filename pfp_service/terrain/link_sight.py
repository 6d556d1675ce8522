"""Line of sight between two units over the terrain grid: whether a controller's radio link has a clear path.

Each end is a mast above the bilinear ground (a unit's own height: a
controller's and its robot's may differ); the sight line
between the two mast tops is clear when no ground along it stands above it
(or within ``clearance_m`` of it: a robot's step keeps a margin,
``teams.SIGHT_CLEARANCE_M``).  Exact for the bilinear surface: within a cell
the ground along the line is a parabola, so it is judged at every grid line
the segment crosses and at each cell's vertex (sampling every half cell
missed crests: the planner saw 21 of 3,000 random pairs over the Jacksboro
DEM that were hidden).  Unknown ground (NaN) and
ground off the grid hide nothing, as in the threats' viewsheds
(docs/terrain.md).  The earth's curvature is left out: at a radio's reach
of a few kilometres it lowers the far end by well under a metre
(``d**2 / 2R``: 0.18 m at 1.5 km), less than a DEM's vertical error.

``tests/unit/test_link_sight.py`` checks it against Franklin's exact ray
(``viewshed.exact_lowest_visible_height``) at grid points.
"""

from __future__ import annotations

import math

import numpy as np

from pfp_service.terrain.grid import TerrainGrid

__all__ = ["MAX_SAMPLES", "sees"]

MAX_SAMPLES = 8192  # grid lines crossed along one sight line at most: a 4 km line over a 1 m grid


def sees(
    grid: TerrainGrid,
    a: tuple[float, float],
    b: tuple[float, float],
    mast_m: float,
    clearance_m: float = 0.0,
    mast_b_m: float | None = None,
) -> bool:
    """Whether ``a`` and ``b`` (metres on the grid's plane), ``mast_m`` and ``mast_b_m`` (``None``: ``mast_m``)
    above the ground, see each other with the sight line at least ``clearance_m`` above the ground between them."""
    t = _crossings(grid, a, b)
    mid = (t[:-1] + t[1:]) / 2.0
    f = np.empty(len(t) + len(mid))
    f[0::2], f[1::2] = t, mid
    z = grid.elevation(a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f)
    za, zb = float(z[0]), float(z[-1])
    if not (math.isfinite(za) or math.isfinite(zb)):
        return True  # both ends on unknown ground: nothing known hides one from the other
    # an end on unknown ground stands as high as the other: the line is judged level from it
    za, zb = (za if math.isfinite(za) else zb), (zb if math.isfinite(zb) else za)
    top_a, top_b = za + mast_m, zb + (mast_m if mast_b_m is None else mast_b_m)
    over = z + clearance_m - (top_a + (top_b - top_a) * f)  # ground above the line (> 0: hidden)
    # between two crossings the ground is one cell's bilinear surface: along the line a parabola,
    # through its ends and middle; its highest point is at an end or at its vertex
    o0, om, o1 = over[0:-1:2], over[1::2], over[2::2]
    curve = 2.0 * o0 + 2.0 * o1 - 4.0 * om
    slope = 4.0 * om - 3.0 * o0 - o1
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(curve < 0.0, -slope / (2.0 * curve), -1.0)
        top = np.where((u > 0.0) & (u < 1.0), o0 - slope * slope / (4.0 * curve), -np.inf)
        # a NaN compares False: unknown ground hides nothing
        return not bool(np.any(over[1:-1] > 0.0) or np.any(top > 0.0))


def _crossings(grid: TerrainGrid, a: tuple[float, float], b: tuple[float, float]) -> np.ndarray:
    """Where (0 to 1, sorted) the segment from ``a`` to ``b`` crosses the grid's lines, with both ends."""
    parts = [np.array([0.0, 1.0])]
    for p0, d, origin in ((a[0], b[0] - a[0], grid.x0_m), (a[1], b[1] - a[1], grid.y0_m)):
        if d == 0.0:
            continue
        i0, i1 = (p0 - origin) / grid.cell_m, (p0 + d - origin) / grid.cell_m
        lo, hi = math.ceil(min(i0, i1)), math.floor(max(i0, i1))
        if hi - lo + 1 > MAX_SAMPLES:
            return np.linspace(0.0, 1.0, MAX_SAMPLES)  # past a radio's reach: evenly, as far as it goes
        parts.append((origin + np.arange(lo, hi + 1) * grid.cell_m - p0) / d)
    return np.unique(np.clip(np.concatenate(parts), 0.0, 1.0))
