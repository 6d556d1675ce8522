"""Right of way: who a moving unit must yield to (``blockers``), and the order that says it (``priority``).

Apart from ``dispersion``, which holds the units it finds here.  A unit
yields to the nearest moving unit of higher priority ahead of it within
``YIELD_AT`` separations whose path meets its own (``deadlocks.meet``),
unless that one goes its way ahead of it (a queue: followed, not yielded
to).  Priority: manned before unmanned (unless ``manned_first`` is off),
then the smaller id; the order is total, so no two units ever yield to
each other.
"""

from __future__ import annotations

import math
from collections.abc import Container

import numpy as np

from pfp_service.core import neighbour_kernels as kernels
from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.wire import Direction, DirectionStatus
from pfp_service.world import deadlocks
from pfp_service.world.units import UnitRecord

__all__ = ["AHEAD", "FOLLOW", "YIELD_AT", "blockers", "priority"]

YIELD_AT = 1.5  # a lower-priority unit closing on a higher one within this many separations holds
# a unit with another straight ahead (within 45 degrees) going its way (within 60) follows it, kept back
# by ``dispersion``'s ``_short``, rather than yielding: right of way is for paths that meet, and a queue
# that holds still at every gap never flows
AHEAD, FOLLOW = math.cos(math.pi / 4), 0.5
_MOVING = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)


def priority(rec: UnitRecord, manned_first: bool) -> tuple[int, str]:
    """The unit's right of way as a sort key: smaller goes first."""
    return (0 if manned_first and rec.kind == "manned" else 1, rec.id)


def blockers(
    index: NeighbourIndex,
    recs: list[UnitRecord],
    held: Container[str],
    manned_first: bool,
    moving: list[Direction],
    rows: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """For each direction, the row of the nearest unit it must yield to (or -1) and how far it is.

    Args:
        index: this tick's neighbour index; ``recs``: its rows' records.
        held: the units that hold now (they do not go under their own right of way).
        moving: the directions judged, their units at ``rows`` of ``index``.
    """
    if not moving:
        return np.zeros(0, dtype=np.intp), np.zeros(0)
    vec = np.array([d.vector for d in moving], dtype=float).reshape(-1, 2)
    at = np.full(len(recs), -1, dtype=np.intp)
    at[rows] = np.arange(len(rows))
    i, j, pair_s = index.near_seps(rows)
    # ahead, and near: NumPy's arithmetic a pair at a time, compiled (``neighbour_kernels.ahead_near``)
    gap, along = np.empty(len(i)), np.empty(len(i))
    close = kernels.ahead_near(index.points, i, j, pair_s, vec, at, YIELD_AT, gap, along)
    i, j, gap, along, pair_s = i[close], j[close], gap[close], along[close], pair_s[close]
    rel = index.points[j] - index.points[i]
    # the pairs left are a few (ahead and near): right of way's order, who goes and their ways read off
    # their records, not arrays over the fleet; the order compared pair by pair is the total order's
    # (``priority``).  A micro-optimisation (bench row: BENCHMARKS.md "A tick's fixed cost", ``python
    # -m benchmarks._march_world --tick 4``): a live tick's few pairs paid some twenty NumPy calls
    best = np.full(len(moving), -1, dtype=np.intp)
    near = np.full(len(moving), np.inf)
    if not len(i):
        return best, near
    ii, jj = i.tolist(), j.tolist()
    rank = {
        u: priority(recs[u], manned_first) for u in {*ii, *jj}
    }  # each unit's once (a big tick: many pairs)
    goes = {u: _goes(recs[u], held) for u in set(jj)}
    yields = [rank[b] < rank[a] and goes[b] for a, b in zip(ii, jj)]
    way = np.array([recs[u].last_vector or (0.0, 0.0) for u in jj], dtype=float).reshape(-1, 2)
    k = at[i]
    ahead = along > AHEAD * gap
    behind = ahead & ((way * vec[k]).sum(axis=1) > FOLLOW)  # in a queue: followed, not yielded to
    keep = np.array(yields, dtype=bool) & ~behind & deadlocks.meet(rel, way - vec[k], pair_s)
    # each direction's nearest: the first of equals, in the pairs' order
    for m, b, g in zip(k[keep].tolist(), j[keep].tolist(), gap[keep].tolist()):
        if g < near[m]:
            best[m], near[m] = b, g
    return best, near


def _goes(rec: UnitRecord, held: Container[str]) -> bool:
    """Whether a unit is moving under its own right of way (not holding, not still)."""
    return rec.last_vector is not None and rec.last_status in _MOVING and rec.id not in held
