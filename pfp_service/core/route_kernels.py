"""The compiled steering along a committed route (``core.route.EscapeRun``): one path, two forms, one rule.

A run's path is its points ``(K, 2)`` or its straight legs (``segs``: one
row ``(ax, ay, dx, dy, last)`` a leg), each read through ``point_of``.
``steer_to`` moves the cursor to the nearest point of a window ahead and heads
for the pursuit point (``_pursuit``); ``steer_step`` judges that heading as
a step (``steprule.judge``), and ``_zone_heading`` keeps it out of keep-out
zones; ``ahead_walk`` walks a ghost along the run for the look-ahead points.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core import steprule, zones
from pfp_service.core.tracking import LEAD_STEPS, PURSUIT_TOLERANCE_STEPS

__all__ = ["ahead_walk", "leg_of", "point_of", "points_of", "steer_step", "steer_to"]


@numba.njit(cache=True, nogil=True, inline="always")
def leg_of(segs: np.ndarray, i: int) -> int:
    """The leg holding point ``i``: the first whose last index is at or past it."""
    lo = 0
    hi = segs.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if segs[mid, 4] >= i:
            hi = mid
        else:
            lo = mid + 1
    return lo


@numba.njit(cache=True, nogil=True, inline="always")
def _on_leg(segs: np.ndarray, leg: int, i: int) -> tuple[float, float]:
    """Point ``i`` of a run kept as legs, on its leg ``leg`` (``leg_of``)."""
    if i == 0:
        return segs[0, 0], segs[0, 1]
    first = segs[leg - 1, 4] if leg > 0 else 0.0
    t = (i - first) / (segs[leg, 4] - first)  # j / m, as polylines.resample divides them
    return segs[leg, 0] + t * segs[leg, 2], segs[leg, 1] + t * segs[leg, 3]


@numba.njit(cache=True, nogil=True, inline="always")
def point_of(path: np.ndarray, segs: np.ndarray, i: int) -> tuple[float, float]:
    """Point ``i`` of a run's path, in either form (``EscapeRun``)."""
    if segs.shape[0] == 0:
        return path[i, 0], path[i, 1]
    return _on_leg(segs, leg_of(segs, i), i)


@numba.njit(cache=True, nogil=True)
def points_of(path: np.ndarray, segs: np.ndarray, n: int) -> np.ndarray:
    out = np.empty((n, 2))
    for i in range(n):
        out[i, 0], out[i, 1] = point_of(path, segs, i)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def steer_to(
    path: np.ndarray,
    segs: np.ndarray,
    n: int,
    cursor: int,
    advisories: int,
    limit: int,
    step: float,
    to_goal: bool,
    lead: int,
    x: float,
    y: float,
) -> tuple[bool, int, int, float, float, float, float]:
    """``EscapeRun.direction``: ``(ok, cursor, advisories, dx, dy, off, ahead)``; not ``ok`` at the exit or past the limit.

    The cursor moves to the nearest of the next points (the first on a
    tie), and the unit heads for the point ``lead`` beyond it; ``off`` is its
    distance from the nearest point, ``ahead`` from the point it heads for.
    The window is 16 points (a unit that moves a step at a time, as a
    preview's, keeps to it), and as many more as the lead is long and as
    the unit could have driven past since the cursor's point, so a fast
    unit reporting seldom is not left behind.  The last step of a ``to_goal`` run ends on the goal:
    ``steprule.judge``'s final approach.
    """
    advisories += 1
    if advisories > limit:
        return False, cursor, advisories, 0.0, 0.0, 0.0, 0.0
    best = math.inf
    i = cursor
    legs = segs.shape[0]
    leg = leg_of(segs, cursor) if legs else 0  # then walked along the window
    cx, cy = point_of(path, segs, cursor)
    window = 16 + (lead - LEAD_STEPS) + 2 * int(min(math.hypot(cx - x, cy - y) / step, 1e9))
    for j in range(cursor, min(cursor + window, n)):
        if legs:
            while segs[leg, 4] < j:
                leg += 1
            px, py = _on_leg(segs, leg, j)
        else:
            px, py = path[j, 0], path[j, 1]
        d = (px - x) * (px - x) + (py - y) * (py - y)
        if d < best:
            best = d
            i = j
    off = math.sqrt(best)
    lx, ly = point_of(path, segs, n - 1)
    if i >= n - 2 and math.hypot(lx - x, ly - y) <= step and not to_goal:
        return False, i, advisories, 0.0, 0.0, off, 0.0
    k = _pursuit(path, segs, n, i, lead, step)
    tx, ty = point_of(path, segs, k)
    dx = tx - x
    dy = ty - y
    norm = math.hypot(dx, dy)
    if norm <= 1e-9 * step:
        return False, i, advisories, 0.0, 0.0, off, 0.0
    return True, i, advisories, dx / norm, dy / norm, off, norm


@numba.njit(cache=True, nogil=True, inline="always")
def _pursuit(path: np.ndarray, segs: np.ndarray, n: int, i: int, lead: int, step: float) -> int:
    """The point a unit nearest point ``i`` heads for: ``lead`` points on, or nearer where the run bends.

    The chord from point ``i`` to it keeps every point between within
    ``PURSUIT_TOLERANCE_STEPS`` steps (halving the lead until it does, never
    below ``LEAD_STEPS``), so a long lead never cuts a bend of the run.
    """
    k = min(i + lead, n - 1)
    low = min(i + LEAD_STEPS, n - 1)
    tol = PURSUIT_TOLERANCE_STEPS * step
    ax, ay = point_of(path, segs, i)
    while k > low:
        bx, by = point_of(path, segs, k)
        cx = bx - ax
        cy = by - ay
        norm = math.hypot(cx, cy)
        ok = True
        for j in range(i + 1, k):
            px, py = point_of(path, segs, j)
            if norm > 0.0:
                d = abs((px - ax) * cy - (py - ay) * cx) / norm
            else:
                d = math.hypot(px - ax, py - ay)
            if d > tol:
                ok = False
                break
        if ok:
            return k
        k = max(i + (k - i) // 2, low)
    return low


@numba.njit(cache=True, nogil=True)
def steer_step(
    path: np.ndarray,
    segs: np.ndarray,
    n: int,
    cursor: int,
    advisories: int,
    limit: int,
    step: float,
    to_goal: bool,
    lead: int,
    unit: np.ndarray,
    x: float,
    y: float,
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
) -> tuple[bool, int, int, int, float, float, float, float, float, float, float, float]:
    """``EscapeRun.steer``: ``steer_to``, then the heading judged as a step (``steprule.judge``)."""
    ok, cursor, advisories, hx, hy, off, ahead = steer_to(
        path, segs, n, cursor, advisories, limit, step, to_goal, lead, x, y
    )
    if not ok:
        return False, cursor, advisories, steprule.GO, 0.0, 0.0, 0.0, 0.0, x, y, off, ahead
    code, dx, dy, dist, move, tx, ty = _zone_heading(
        path, segs, n, cursor, unit, x, y, hx, hy, edges, offsets, circles, boxes
    )
    return True, cursor, advisories, code, dx, dy, dist, move, tx, ty, off, ahead


@numba.njit(cache=True, nogil=True)
def _zone_heading(
    path: np.ndarray,
    segs: np.ndarray,
    n: int,
    cursor: int,
    unit: np.ndarray,
    x: float,
    y: float,
    hx: float,
    hy: float,
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
) -> tuple[int, float, float, float, float, float, float]:
    """The heading ``(hx, hy)`` judged as a step; among zones, one that would touch a zone is replaced.

    A run's own segments keep out of every zone (``Escaper._judge``), but
    heading two points ahead cuts its corners: then head for the run's next
    point, then its nearest; failing both, the step is cut short of the zone
    (``steprule.CLEAR_STEPS``).
    """
    code, dx, dy, dist, move, tx, ty = steprule.judge(unit, x, y, hx, hy, 1.0, steprule.HEADING)
    if boxes.shape[0] == 0 or code != steprule.GO or move <= 0.0:
        return code, dx, dy, dist, move, tx, ty
    if zones.point_zone(edges, offsets, circles, boxes, x, y, 0.0)[0] <= zones.TOUCH_M:
        return code, dx, dy, dist, move, tx, ty  # in a zone: the run is the way out of it
    t, z = zones.segment_hit(edges, offsets, circles, boxes, x, y, tx, ty)
    if z < 0:
        return code, dx, dy, dist, move, tx, ty
    for k in (cursor + 1, cursor):
        if k >= n:
            continue
        px, py = point_of(path, segs, k)
        ax = px - x
        ay = py - y
        norm = math.hypot(ax, ay)
        if norm <= 1e-9 * unit[steprule.STEP]:
            continue
        c2, d2x, d2y, dist2, move2, t2x, t2y = steprule.judge(
            unit, x, y, ax / norm, ay / norm, 1.0, steprule.HEADING
        )
        if c2 == steprule.GO and move2 > norm:  # no farther than the point itself: the run's own segment
            move2 = norm
            t2x = px
            t2y = py
        if zones.segment_hit(edges, offsets, circles, boxes, x, y, t2x, t2y)[1] < 0:
            return c2, d2x, d2y, dist2, move2, t2x, t2y
    keep = max(t * move - steprule.CLEAR_STEPS * unit[steprule.STEP], 0.0)
    return code, dx, dy, dist, keep, x + dx * keep, y + dy * keep


@numba.njit(cache=True, nogil=True)
def ahead_walk(
    path: np.ndarray,
    segs: np.ndarray,
    n: int,
    cursor: int,
    advisories: int,
    limit: int,
    step: float,
    to_goal: bool,
    lead: int,
    unit: np.ndarray,
    x: float,
    y: float,
    steps: int,
    out: np.ndarray,
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
) -> int:
    """``EscapeRun.ahead``'s loop: positions written to ``out``, or -1 where the run would end."""
    out[0, 0] = x
    out[0, 1] = y
    for k in range(steps):
        if steprule.judge(unit, x, y, 0.0, 0.0, 0.0, steprule.CHECK)[0] != steprule.GO:
            return k + 1  # arrived, out of bounds or not finite: the ghost stops here
        ok, cursor, advisories, hx, hy, _off, _to_pursuit = steer_to(
            path, segs, n, cursor, advisories, limit, step, to_goal, lead, x, y
        )
        if not ok:
            return -1
        _code, _dx, _dy, _dist, _move, x, y = _zone_heading(
            path, segs, n, cursor, unit, x, y, hx, hy, edges, offsets, circles, boxes
        )
        out[k + 1, 0] = x
        out[k + 1, 1] = y
    return steps + 1
