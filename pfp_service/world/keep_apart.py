"""Dispersion's last word on a moving direction: it never takes a unit into another's ``KEEP`` separations.

Apart from ``dispersion`` (the right of way and deadlocks), which calls it
last in each ``apply``.  ``cut`` also says which units it left cut to
nothing, and by whom: two units each stopped by the other's disc hold each
other (``dispersion`` makes two going round units at rest so one deadlock).

The margin beyond the separation is for a neighbour that moves meanwhile,
perhaps towards the unit; a unit giving way to another (yielding, or
backing off from it) does not come at it, so against the unit it gives way
to its disc is the separation alone (``GIVEN``).  With the margin, a unit
holding still for another stopped that very unit whose way leaned into
its disc, and each held the other for good (the gaps crowd's seed 4).  A unit
already on a neighbour's disc (where the cut parks it) or inside it keeps
only the margin's inner half (``INSIDE``): parked on the edge, any way
leaning into the disc however slightly was cut to nothing, and in a crowd
packed at the margin (the gaps crowd's column at its middle gap) a unit
stood while the neighbours it touched stood.  A step of 5 m still leaves
such a pair 0.95 separations apart.

A neighbour going the unit's way moves too (``keep_apart_kernels.cut``): against a
neighbour on its own way in this tick (en route or escaping, as the unit
is), within 60 degrees of the unit's (``WITH``, as ``right_of_way.FOLLOW``),
the unit's ray is cut as the two would move, the neighbour along its way
as far as the cut with every neighbour standing leaves it, at the unit's
speed; once within the margin, that disc is the separation alone; and
wherever the neighbour stands, the unit keeps its separation from it.
Treated as standing for the tick, a slower neighbour beside the unit,
within the margin, held it while it crept on, in every column packed at
the margin (the gaps crowd's seeds 9-16, issue 33: seed 11's ``u0128``
beside ``u0131``).  Moving as told, the two keep their separation; if the
neighbour stands after all, the unit is at its separation from it; a pair
comes no nearer than its separation less a step (0.9 with 5 m steps) in
the worst case, and 0.98 in the gaps crowd's 24 seeds.

Two ways out of a stop, for the units that give way: a back-off the cut
leaves nothing of turns to the nearest free way off it, still away from
the other unit (``free_ways``: backing off from nothing, the deadlock
formed again as it ended); and a unit holding still for another whose disc
stops that very unit moves out of its way, square to it (``make_room``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import msgspec
import numpy as np

from pfp_service.core import keep_apart_kernels as kernels
from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.wire import Direction, DirectionStatus
from pfp_service.world.deadlocks import Hold, aside_vector, held

__all__ = [
    "GIVEN",
    "INSIDE",
    "KEEP",
    "TURNS_DEG",
    "WITH",
    "cut",
    "free_way",
    "free_ways",
    "giving_way",
    "make_room",
]

KEEP = 1.1  # no direction drives a unit within this many separations of another
GIVEN = 1.0  # ... nor within its separation of a unit giving way to it (which does not come at it)
TURNS_DEG = (30.0, -30.0, 60.0, -60.0, 90.0, -90.0)  # ``free_way``'s turns, nearest first
INSIDE = 1.05  # ... nor, once on or within that disc, within this many separations of the other
WITH = 0.5  # a neighbour on its own way within 60 degrees of the unit's goes its way: it moves meanwhile
_GRAZE_M = 1e-6  # along a disc's tangent: rounding, not a way into it
_OWN = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)  # on its own way: no hold turns it after the cut
_RULE = (KEEP, GIVEN, INSIDE, WITH, _GRAZE_M)  # for the compiled cut (``core.keep_apart_kernels``)
_NONE = np.zeros(0, dtype=np.intp)  # no unit gives way, for the compiled cut


def cut(
    index: NeighbourIndex,
    rows: np.ndarray,
    directions: list[Direction],
    go: list[int],
    gives_way: np.ndarray | None = None,
) -> list[tuple[int, int]]:
    """Cut each of ``directions[go]`` (the units at ``index`` rows ``rows``) where it would enter a neighbour's disc.

    A direction's ray against every neighbour's disc of ``KEEP`` times the
    pair's separation, in one compiled pass (``keep_apart_kernels.cut``,
    a tick's few pairs without NumPy's per-call cost): the unit goes no further
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
    ways = np.array(
        [(*d.vector, d.status in _OWN, d.reach_m or 0.0) for d in (directions[k] for k in go)], dtype=float
    ).reshape(-1, 4)
    i, j, pair_s = index.near_seps(rows)
    safe, held = kernels.cut(
        index.points,
        rows,
        i,
        j,
        pair_s,
        ways,
        _NONE if gives_way is None else gives_way,
        _RULE,
        np.empty(len(i)),
    )
    for m, reach in enumerate(safe.tolist()):
        if math.isfinite(reach):
            d = directions[go[m]]
            if d.reach_m is None or reach < d.reach_m:
                directions[go[m]] = msgspec.structs.replace(d, reach_m=reach)
    return [(go[m], jj) for m, jj in held.tolist()]


def free_way(
    index: NeighbourIndex, row: int, way: tuple[float, float], away: np.ndarray, reach_m: float
) -> tuple[float, float, float] | None:
    """A turn of ``way`` (``TURNS_DEG``, nearest first) for the unit at ``row``, whose ``way`` the cut
    leaves nothing of: the one ``cut`` would leave the longest reach, up to ``reach_m``, among those not
    turning against ``away``; ``(dx, dy, reach)``, or ``None`` when each is cut to nothing too.

    For a unit backing off: a back-off cut to nothing gives no ground, and the deadlock it was to
    clear forms again as it ends.
    """
    i, j, pair_s = index.near_seps(np.array([row], dtype=np.intp))
    t = np.radians(np.array(TURNS_DEG))
    wx, wy = way
    turns = np.stack([wx * np.cos(t) - wy * np.sin(t), wx * np.sin(t) + wy * np.cos(t)], axis=1)
    m = len(i)
    enter = np.empty((len(t), m))
    kernels.entries(
        index.points,
        np.tile(i, len(t)),
        np.tile(j, len(t)),
        np.tile(pair_s, len(t)),
        np.repeat(turns, m, axis=0),
        _NONE,
        _RULE,
        enter.reshape(-1),  # a view: the kernel writes ``enter``
    )
    reach = np.minimum(enter.min(axis=1, initial=np.inf), reach_m)
    reach[turns @ np.asarray(away, dtype=float) < 0.0] = 0.0
    best = int(np.argmax(reach))  # the first of the longest: the nearest turn
    if not reach[best] > _GRAZE_M:
        return None
    return float(turns[best, 0]), float(turns[best, 1]), float(reach[best])


def giving_way(
    index: NeighbourIndex,
    row: Mapping[str, int],
    holds: Mapping[str, Hold],
    directions: list[Direction],
    moving: list[int],
) -> np.ndarray | None:
    """Each ``index`` row's unit it gives way to in this tick (``-1``: none; ``None``: no unit does), for
    ``cut``: a unit yielding to another (``holds``), or backing off from it, whose direction does not close
    on it.  ``row``: each unit's row; ``moving``: the positions in ``directions`` judged in this tick."""
    gives_way = None
    for k in moving:
        d = directions[k]
        hold = holds.get(d.unit)
        if d.status is not DirectionStatus.YIELDING or hold is None or hold.round or hold.other not in row:
            continue
        i, j = row[d.unit], row[hold.other]
        rx, ry = (index.points[i] - index.points[j]).tolist()
        if d.vector[0] * rx + d.vector[1] * ry < 0.0:  # coming at it: the margin stands
            continue
        if gives_way is None:
            gives_way = np.full(len(index.points), -1, dtype=np.intp)
        gives_way[i] = j
    return gives_way


def free_ways(
    index: NeighbourIndex,
    row: Mapping[str, int],
    holds: Mapping[str, Hold],
    directions: list[Direction],
    stopped: list[tuple[int, int]],
    now: float,
) -> list[tuple[int, int]]:
    """Turn each back-off that ``cut`` left nothing of (``stopped``) to a free way off it (``free_way``),
    still away from the unit it backs off from, in place; the stopped pairs left."""
    turned: set[int] = set()
    for k in sorted({k for k, _ in stopped}):
        d = directions[k]
        hold = holds.get(d.unit)
        if hold is None or hold.round or not hold.until > now or hold.other not in row:
            continue
        i, j = row[d.unit], row[hold.other]
        pair = float(index.pair_seps(np.array([i]), np.array([j]))[0])
        way = free_way(index, i, d.vector, index.points[i] - index.points[j], pair)
        if way is not None:
            vx, vy, reach = way
            heading = math.degrees(math.atan2(vx, vy)) % 360.0
            directions[k] = msgspec.structs.replace(d, vector=(vx, vy), heading_deg=heading, reach_m=reach)
            turned.add(k)
    return [(k, j) for k, j in stopped if k not in turned]


def make_room(
    index: NeighbourIndex,
    row: Mapping[str, int],
    directions: list[Direction],
    moving: list[int],
    stopped: list[tuple[int, int]],
    gives_way: np.ndarray | None,
) -> list[int]:
    """Send each unit holding still for another whose disc stops (``stopped``) that very unit out of its
    way, square to it (``deadlocks.aside_vector``), in place; their positions in ``directions``.

    A unit holding still in the way of the unit it yields to held both: that
    one waited at its disc, it waited for that one to pass.
    """
    if gives_way is None:
        return []
    blocking = {j: k for k, j in stopped if gives_way[j] == row[directions[k].unit]}
    made: list[int] = []
    for m in moving:
        d = directions[m]
        j = row[d.unit]
        if j not in blocking or d.vector != (0.0, 0.0):
            continue
        other = directions[blocking.pop(j)]
        vec = aside_vector(index.points[j] - index.points[row[other.unit]], other.vector)
        pair = float(index.pair_seps(np.array([j]), np.array([row[other.unit]]))[0])
        directions[m] = held(
            d, vec, pair, (d.reason or "").replace("; goes when", "; making room, goes when")
        )
        cut(index, np.array([j], dtype=np.intp), directions, [m], gives_way)
        made.append(m)
    return made
