"""Compiled neighbour questions for ``core.dispersion.NeighbourIndex``: a few rows' neighbours in one pass.

A live tick asks the neighbours of a few units (its reports) of an index
whose k-d tree was kept from where the units were a few ticks before
(``NeighbourIndex``'s ``moved_from``).  The tree's answer is then only a
superset (its query widened by how far any unit has gone since), measured
again at the units' positions with the tree's own test: the squared
distance at most the squared reach.  One compiled pass over the points with
that very test gives the same neighbours in the same order, without the
tree's query, a list per row and the arrays that measured them.  And a
tick's pairs' separations (``pair_seps``): ``pair_separation``'s NumPy, a
dozen calls for the tick's few score pairs, as one compiled loop.  Issue 33,
a tick's fixed cost (bench row: BENCHMARKS.md "A tick's fixed cost",
``python -m benchmarks._march_world --tick 4``).  No fast-math: the same
floating-point operations as NumPy's, in its order, so the same numbers.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["ahead_near", "pair_seps", "pair_terms", "within"]


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


@numba.njit(cache=True, nogil=True, inline="always")
def _larger(a: float, b: float) -> float:
    """``np.maximum``'s: NaN when either is."""
    if a != a or b != b:
        return math.nan
    return a if a >= b else b


@numba.njit(cache=True, nogil=True, inline="always")
def _smaller(a: float, b: float) -> float:
    """``np.minimum``'s: NaN when either is."""
    if a != a or b != b:
        return math.nan
    return a if a <= b else b


@numba.njit(cache=True, nogil=True, error_model="numpy")  # a separation of 0: NumPy's inf and NaN, no raise
def pair_seps(
    points: np.ndarray,
    seps: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    team: np.ndarray,
    team_sep: np.ndarray,
    goals: np.ndarray,
    relax: float,
    relax_over: float,
    out: np.ndarray,
) -> None:
    """``core.dispersion.pair_separation`` of each pair ``(i[k], j[k])`` into ``out[k]``: the same operations
    in its order, a pair at a time.  ``team`` empty: no teams; ``goals`` empty: no goals."""
    teams, with_goals = team.shape[0] > 0, goals.shape[0] > 0
    for k in range(i.shape[0]):
        a, b = i[k], j[k]
        s = _larger(seps[a], seps[b])
        if teams and team[a] == team[b] and team[a] >= 0:
            s = team_sep[a]
        if with_goals:
            gap = math.hypot(goals[a, 0] - goals[b, 0], goals[a, 1] - goals[b, 1])
            far = _larger(
                math.hypot(points[a, 0] - goals[a, 0], points[a, 1] - goals[a, 1]),
                math.hypot(points[b, 0] - goals[b, 0], points[b, 1] - goals[b, 1]),
            )
            floor = _smaller(s, relax * gap)
            relaxed = floor + (s - floor) * _smaller(far / (relax_over * s), 1.0)
            if math.isfinite(relaxed):
                s = relaxed
        out[k] = s


@numba.njit(cache=True, nogil=True, error_model="numpy")
def pair_terms(
    points: np.ndarray, pair_s: np.ndarray, i: np.ndarray, j: np.ndarray, reach: float, out: np.ndarray
) -> None:
    """``core.dispersion._pair_terms`` added into ``out`` (``(N, 2)`` zeros): each pair's share of row
    ``i[k]``'s gradient, summed in the pairs' order as ``np.bincount`` sums them."""
    for k in range(i.shape[0]):
        a, b = i[k], j[k]
        if a == b:
            continue
        dx = points[a, 0] - points[b, 0]
        dy = points[a, 1] - points[b, 1]
        d = math.hypot(dx, dy)
        rho = reach * pair_s[k]
        if not d < rho:
            continue
        if d == 0.0:  # -grad: the lower index goes west
            out[a, 0] += 1.0 if a < b else -1.0
            out[a, 1] += 0.0
            continue
        w = (1.0 - d / rho) / d
        out[a, 0] += -w * dx
        out[a, 1] += -w * dy


@numba.njit(cache=True, nogil=True)
def ahead_near(
    points: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    pair_s: np.ndarray,
    vec: np.ndarray,
    at: np.ndarray,
    near: float,
    gap: np.ndarray,
    along: np.ndarray,
) -> np.ndarray:
    """For each pair ``(i[k], j[k])``: the gap between the two (``np.hypot``) into ``gap[k]``, how far ``j``
    lies along ``i``'s way ``vec[at[i[k]]]`` into ``along[k]``, and whether it is ahead (``along > 0``) and
    within ``near`` pair separations: right of way's first look at a tick's pairs (``world.dispersion``),
    NumPy's operations pair by pair."""
    close = np.zeros(i.shape[0], dtype=np.bool_)
    for k in range(i.shape[0]):
        a, b, m = i[k], j[k], at[i[k]]
        rx = points[b, 0] - points[a, 0]
        ry = points[b, 1] - points[a, 1]
        g = math.hypot(rx, ry)
        w = rx * vec[m, 0] + ry * vec[m, 1]
        gap[k], along[k] = g, w
        close[k] = w > 0.0 and g < near * pair_s[k]
    return close
