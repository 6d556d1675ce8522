"""What each threat sees over a ``TerrainGrid``: its window of lowest visible heights, for ``ThreatField``.

``TerrainSight(grid, height_m)`` is a ``core.visibility.Sight``: asked for a
threat and the box of its reach, it runs the viewshed sweep
(``viewshed.lowest_visible_height``, Wang 2000) over the grid's cells in that
box, from the grid point nearest the threat, at the threat's
``observer_height_m`` above the ground, and returns the window.  The sweep
sees only cells in the box: a sight line from inside a convex box to a point
inside it stays inside it.  A window is computed once per threat position,
eye and reach, and kept (``cache_size`` of them, least recently used out).
The heights do not depend on the target: a unit of another height takes the
same window at its own (``core.visibility.Window.at``), never a second sweep.

A threat off the grid, or standing on unknown ground, gets no window: it sees
everywhere (the safe side, as unknown ground hides nothing in a viewshed).

Bounded windows.  A window travels in its threat's packed row, and the rows
are as wide as the widest, so a window of the grid's own cells would cost
8 bytes a cell a threat: 8 MB for a threat reaching 5 km on 10 m cells.  The
sweep runs on the grid's cells, then the window keeps at most
``WINDOW_SIDE`` heights a side: its cell is the smallest whole multiple
``f`` of the grid's that fits, and each of its heights is the *least* of
the grid's within half a window cell (``f // 2`` cells) of it, so a coarse
window never hides a unit that a fine one would show near there (the safe
side).  The kernels interpolate it bilinearly and differentiate exactly
that surface, as for any window.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import Any

import numpy as np

from pfp_service.core.visibility import Window, softness_for
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.viewshed import lowest_visible_height

__all__ = ["WINDOW_SIDE", "TerrainSight", "coarsen", "softness_for"]

WINDOW_SIDE = 200  # a window's heights a side at most: 100 threats' rows are then 32 MB (docs/terrain.md)


class TerrainSight:
    """Per threat, the lowest visible heights over ``grid`` within its reach (a ``core.visibility.Sight``)."""

    def __init__(
        self, grid: TerrainGrid, height_m: float, curvature: float = 0.0, cache_size: int = 256
    ) -> None:
        if not (height_m >= 0 and math.isfinite(height_m)):
            raise ValueError(f"a unit's height must be metres >= 0, not {height_m}")
        self.grid = grid
        self.height_m = float(height_m)
        self.softness_m = softness_for(self.height_m)
        self.curvature = float(curvature)
        self._cache: OrderedDict[tuple[float, ...], Window | None] = OrderedDict()
        self._cache_size = cache_size

    def __call__(self, threat: Any, box: tuple[float, float, float, float]) -> Window | None:
        key = (float(threat.xi[0]), float(threat.xi[1]), float(threat.observer_height_m), *box)
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        got = self._window(threat, box)
        self._cache[key] = got
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return got

    def _window(self, threat: Any, box: tuple[float, float, float, float]) -> Window | None:
        g = self.grid
        ny, nx = g.shape
        c = g.cell_m
        i0 = max(0, math.floor((box[0] - g.x0_m) / c))
        i1 = min(nx - 1, math.ceil((box[2] - g.x0_m) / c))
        k0 = max(0, math.floor((box[1] - g.y0_m) / c))
        k1 = min(ny - 1, math.ceil((box[3] - g.y0_m) / c))
        oi = round((threat.xi[0] - g.x0_m) / c)
        ok = round((threat.xi[1] - g.y0_m) / c)
        if not (i0 <= oi <= i1 and k0 <= ok <= k1) or i1 - i0 < 1 or k1 - k0 < 1:
            return None  # off the grid: it sees everywhere
        z = g.z[k0 : k1 + 1, i0 : i1 + 1]
        if not math.isfinite(z[ok - k0, oi - i0]):
            return None  # on unknown ground
        low = lowest_visible_height(
            z, (ok - k0, oi - i0), float(threat.observer_height_m), math.inf, c, c, self.curvature
        )
        f = max(1, math.ceil((max(low.shape) - 1) / (WINDOW_SIDE - 1)))
        return Window(
            g.x0_m + i0 * c, g.y0_m + k0 * c, f * c, coarsen(low, f), self.height_m, self.softness_m
        )


def coarsen(low: np.ndarray, f: int) -> np.ndarray:
    """Every ``f``-th height of ``low`` a side, each the least within ``f // 2`` cells of it (unknown as 0).

    The last row and column reach the window's end or just past it (the
    edge's heights carried on), so the coarse window covers the fine one.
    Only the rows and columns kept are reduced (rows first, then columns of
    those), not a filter over every fine cell: on 1,001 x 1,001 cells it is
    a few per cent of the sweep, where a full ``minimum_filter`` cost twice
    the sweep (BENCHMARKS.md, "Terrain"; docs/terrain.md).  A NaN (unknown,
    or beyond the radius) makes its neighbourhood 0, as ``nan_to_num`` first
    would: every height is ``>= 0``.
    """
    if f == 1:
        return low
    ny, nx = low.shape
    my, mx = -(-(ny - 1) // f) + 1, -(-(nx - 1) // f) + 1
    near = np.arange(-(f // 2), f // 2 + 1)
    rows = np.clip(np.arange(my)[:, None] * f + near, 0, ny - 1)  # clipped: the edge carried on
    cols = np.clip(np.arange(mx)[:, None] * f + near, 0, nx - 1)
    out = low[rows].min(axis=1)[:, cols].min(axis=2)
    return np.ascontiguousarray(np.nan_to_num(out, nan=0.0))
