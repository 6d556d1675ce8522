"""Compiled neighbour questions for ``core.dispersion.NeighbourIndex``: a few rows' neighbours in one pass.

A live tick asks the neighbours of a few units (its reports) of an index
whose k-d tree was kept from where the units were a few ticks before
(``NeighbourIndex``'s ``moved_from``).  The tree's answer is then only a
superset (its query widened by how far any unit has gone since), measured
again at the units' positions with the tree's own test: the squared
distance at most the squared reach.  One compiled pass over the points with
that very test gives the same neighbours in the same order, without the
tree's query, a list per row and the arrays that measured them (issue 33:
a tick's fixed cost; bench row ``python -m benchmarks._march_world --tick 4``).
No fast-math: the same floating-point operations as NumPy's, in its order.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["within"]


@numba.njit(cache=True, nogil=True)
def within(points: np.ndarray, rows: np.ndarray, reach2: float, found: np.ndarray, counts: np.ndarray) -> int:
    """Each of ``rows``' neighbours: every point ``j`` (itself included) with
    ``dx * dx + dy * dy <= reach2``, ascending, written one row after another into ``found``
    (at least ``len(rows) * len(points)`` long), each row's count into ``counts``; how many in all."""
    n = points.shape[0]
    at = 0
    for a in range(rows.shape[0]):
        px = points[rows[a], 0]
        py = points[rows[a], 1]
        c = 0
        for b in range(n):
            dx = px - points[b, 0]
            dy = py - points[b, 1]
            if dx * dx + dy * dy <= reach2:
                found[at] = b
                at += 1
                c += 1
        counts[a] = c
    return at
