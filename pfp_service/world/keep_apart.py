"""Dispersion's last word on a moving direction: it never takes a unit within ``KEEP`` separations of another.

Apart from ``dispersion`` (the right of way and deadlocks), which calls it
last in each ``apply``.  ``cut`` also says which units it left cut to
nothing, and by whom: two units each stopped by the other's disc hold each
other (``dispersion`` makes two going round units at rest so one deadlock).

The margin beyond the separation is for a neighbour that moves meanwhile,
perhaps towards the unit; a unit giving way to another (yielding, or
backing off from it) does not come at it, so against the unit it gives way
to its disc is the separation alone (``GIVEN``).  With the margin, a unit
holding still for another stopped that very unit whose way leaned into
its disc, and each held the other for good (the gaps crowd's seed 4).
"""

from __future__ import annotations

import msgspec
import numpy as np

from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.wire import Direction

__all__ = ["GIVEN", "GRAZE_M", "KEEP", "cut", "free_m"]

KEEP = 1.1  # no direction drives a unit within this many separations of another
GIVEN = 1.0  # ... nor within its separation of a unit giving way to it (which does not come at it)
GRAZE_M = 1e-6  # along a disc's tangent: rounding, not a way into it


def cut(
    index: NeighbourIndex,
    rows: np.ndarray,
    directions: list[Direction],
    go: list[int],
    gives_way: np.ndarray | None = None,
) -> list[tuple[int, int]]:
    """Cut each of ``directions[go]`` (the units at ``index`` rows ``rows``) where it would enter a neighbour's disc.

    A direction's ray against every neighbour's disc of ``KEEP`` times the
    pair's separation, in one vectorised pass: the unit goes no further
    than the disc's edge (0, holding, when it is inside one and closing),
    so no direction ever drives a unit into another's separation, whatever
    pushes it.  The margin is for the other unit, which moves meanwhile.

    Args:
        index: this tick's neighbour index.
        rows: each moving direction's row in ``index``.
        directions: the tick's directions, cut in place; those at ``go`` have a non-zero vector.
        go: the positions in ``directions`` of the moving ones, in the order of ``rows``.
        gives_way: for each ``index`` row, the row of the unit it gives way to in this tick (``-1``:
            none); that unit keeps only ``GIVEN`` separations from it (``None``: no unit gives way).

    Returns:
        Each unit left cut to nothing (its position in ``directions``) with
        the row of every neighbour whose disc stops it, one pair each.
    """
    at = np.full(len(index.points), -1, dtype=np.intp)
    at[rows] = np.arange(len(rows))
    vec = np.array([directions[k].vector for k in go], dtype=float).reshape(-1, 2)
    i, j, pair_s = index.near_seps(rows)
    n = at[i]
    enter = _entries(index, i, j, pair_s, vec[n], gives_way)
    hit = np.isfinite(enter)
    safe = np.full(len(go), np.inf)
    np.minimum.at(safe, n[hit], enter[hit])
    for m in np.flatnonzero(np.isfinite(safe)).tolist():
        k, reach = go[m], float(safe[m])
        d = directions[k]
        if d.reach_m is None or reach < d.reach_m:
            directions[k] = msgspec.structs.replace(d, reach_m=reach)
    held = (enter <= GRAZE_M) & (safe[n] <= GRAZE_M)
    return [(go[m], jj) for m, jj in zip(n[held].tolist(), j[held].tolist())]


def free_m(index: NeighbourIndex, row: int, vec: tuple[float, float]) -> float:
    """How far the unit at ``row`` could go along ``vec`` (a unit vector) before ``cut`` would stop it, in
    metres (``inf``: nothing in the way); 0 when it would be cut to nothing."""
    i, j, pair_s = index.near_seps(np.array([row], dtype=np.intp))
    enter = _entries(index, i, j, pair_s, np.broadcast_to(np.asarray(vec, dtype=float), (len(i), 2)), None)
    return float(enter.min(initial=np.inf))


def _entries(
    index: NeighbourIndex,
    i: np.ndarray,
    j: np.ndarray,
    pair_s: np.ndarray,
    vec: np.ndarray,
    gives_way: np.ndarray | None,
) -> np.ndarray:
    """How far along ``vec`` (one per pair) each unit ``i`` enters ``j``'s disc (``inf``: never)."""
    rel = index.points[j] - index.points[i]
    along = (rel * vec).sum(axis=1)
    keep_m = KEEP * pair_s
    if gives_way is not None:
        keep_m = np.where(gives_way[j] == i, GIVEN * pair_s, keep_m)
    across2 = (rel * rel).sum(axis=1) - along * along
    hit = (along > GRAZE_M) & (across2 < keep_m * keep_m)
    enter = np.full(len(rel), np.inf)
    enter[hit] = np.maximum(along[hit] - np.sqrt(np.maximum(keep_m[hit] ** 2 - across2[hit], 0.0)), 0.0)
    return enter
