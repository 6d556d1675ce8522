"""Line of sight between two units over the terrain grid: whether a controller's radio link has a clear path.

Each end is a mast ``mast_m`` above the bilinear ground; the sight line
between the two mast tops is clear when no ground sampled along it (every
half cell, both ends excluded) stands above it (or within ``clearance_m`` of
it: a robot's step keeps a margin, ``teams.SIGHT_CLEARANCE_M``).  Unknown ground (NaN) and
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

MAX_SAMPLES = 8192  # samples along one sight line at most: a 4 km line over a 1 m grid


def sees(
    grid: TerrainGrid, a: tuple[float, float], b: tuple[float, float], mast_m: float, clearance_m: float = 0.0
) -> bool:
    """Whether ``a`` and ``b`` (metres on the grid's plane), each ``mast_m`` above the ground, see each other
    with the sight line at least ``clearance_m`` above the ground between them."""
    far = math.dist(a, b)
    n = min(MAX_SAMPLES, max(2, math.ceil(far / (grid.cell_m / 2.0)) + 1))
    f = np.linspace(0.0, 1.0, n)
    z = grid.elevation(a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f)
    za, zb = float(z[0]), float(z[-1])
    if not (math.isfinite(za) or math.isfinite(zb)):
        return True  # both ends on unknown ground: nothing known hides one from the other
    # an end on unknown ground stands as high as the other: the line is judged level from it
    za, zb = (za if math.isfinite(za) else zb), (zb if math.isfinite(zb) else za)
    line = (za + mast_m) + (zb - za) * f[1:-1]
    with np.errstate(invalid="ignore"):
        return not bool(
            np.any(z[1:-1] + clearance_m > line)
        )  # a NaN compares False: unknown ground hides nothing
