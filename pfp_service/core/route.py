"""A committed route and the compiled steering along it: the path, the cursor, the pursuit point.

``EscapeRun`` is what a stepper follows once it has committed to a path: an
escape from a trap, a way out of a core or zone, a route round a trap, or a
live unit's tracked descent (``core.tracking``).  It keeps its path as points
or as straight legs, and steers from wherever the unit reports: the cursor
moves to the nearest point of a window ahead, and the unit heads for the
pursuit point ``lead`` points past it (``_pursuit``: nearer where the path
bends).  Every step it advises is judged by ``steprule.judge``, so arrival,
bounds and keep-out zones are the same rule as descent's.
"""

from __future__ import annotations

import bisect
import math

import numba
import numpy as np

from pfp_service.core import steprule, zones
from pfp_service.core.advice import StepStatus
from pfp_service.core.foresight import Foresight, Outcome
from pfp_service.core.grid import pieces
from pfp_service.core.tracking import LEAD_STEPS, PURSUIT_TOLERANCE_STEPS, SIMPLIFY_STEPS, Route, simplify
from pfp_service.core.zones import ZoneSet

__all__ = ["NO_LIMIT", "NO_POINTS", "EscapeRun", "descent_route", "legs", "path_length"]

NO_LIMIT = 1 << 62  # a tracked route's advisory limit: none (it is left by its corridor, never by a count)

_NO_ZONES = ZoneSet()


class EscapeRun:
    """A committed escape: the path to steer along and how far along the unit is.

    ``to_goal``: the path ends at the goal, so at its end the unit is steered
    on to the goal (arrival is judged along the route) instead of being handed
    back to plain descent, whose threat gradient near the goal may be far
    stronger than the goal's pull.

    The path is kept in one of two forms, each read through ``_point``:
    ``path``, its points ``(K, 2)``; or, for a route made of long straight
    legs (``along``: a global route, a way out of a core), ``segs``, one row
    ``(ax, ay, dx, dy, last)`` a leg, whose points are exactly those
    ``grid.resample`` makes (``a + (j / m) d``, ``j = 1..m``; ``last`` the
    index of the leg's final point).  A 2 km route at a 1 m step is then a
    few hundred bytes instead of 30 KB, in the world's books and in every
    worker's answer.
    """

    __slots__ = (
        "_after",
        "_said",
        "advisories",
        "ahead_m",
        "cursor",
        "lead",
        "limit",
        "n",
        "name",
        "off_m",
        "path",
        "route",
        "segs",
        "step",
        "to_goal",
        "zones",
    )

    def __init__(
        self,
        name: str,
        path: np.ndarray,
        step: float,
        to_goal: bool = False,
        *,
        segs: np.ndarray | None = None,
    ) -> None:
        self.name = name
        # never changed once made (copies share them): 16 bytes a point, or 40 a leg
        if segs is None:
            self.path: np.ndarray = np.array(path, dtype=np.float64).reshape(-1, 2)
            self.segs: np.ndarray = _NO_SEGS
            self.n = len(self.path)
        else:
            self.path = NO_POINTS
            self.segs = np.ascontiguousarray(segs, dtype=np.float64).reshape(-1, 5)
            self.n = int(self.segs[-1, 4]) + 1
        self.path.flags.writeable = False
        self.segs.flags.writeable = False
        self.cursor = 0
        self.advisories = 0
        self.limit = 2 * self.n + 20
        self.step = step
        self.to_goal = to_goal
        self.zones: ZoneSet = _NO_ZONES  # the zones it was last steered among (``steer``), for ``ahead``
        self.route = Route.ESCAPE  # what it is, for the direction (the stepper names the others)
        self.lead = LEAD_STEPS  # the pursuit point is this many points past the nearest (``tracking``)
        self.off_m = 0.0  # at the last ``steer``: the unit's distance from the nearest point of the run
        self.ahead_m = 0.0  # ... and from the pursuit point
        # per leg (or point): the run's length from it to the end, each length, each leg's last index; its end
        self._after: tuple[list[float], list[float], list[float], tuple[float, float]] | None = None
        self._said: tuple[StepStatus, str] | None = None  # the status and reason it gives (``said``)

    @classmethod
    def along(cls, name: str, corners: np.ndarray, step: float, to_goal: bool = False) -> EscapeRun:
        """The run along ``corners`` resampled at ``step`` (``grid.resample``), kept as its legs."""
        return cls(name, NO_POINTS, step, to_goal, segs=legs(corners, step))

    def said(self) -> tuple[StepStatus, str]:
        """The status and the reason, in words, of a unit on this run (made once: ``route`` is set by then)."""
        said = self._said
        if said is None:
            route = self.route
            if route.escaping:
                said = (StepStatus.ESCAPING, f"{route.words}: {self.name}")
            else:
                said = (StepStatus.EN_ROUTE, route.words)
            self._said = said
        return said

    def end_to(self, goal: tuple[float, float]) -> float:
        """The straight distance from the run's end to ``goal`` (per report on the live tick: the end kept once)."""
        table = self._after
        if table is None:
            self.left_m()
            table = self._after
            assert table is not None
        ex, ey = table[3]
        return math.hypot(goal[0] - ex, goal[1] - ey)

    def left_m(self) -> float:
        """The length of the run from its cursor to its end, metres (the route a unit has still to drive).

        Per unit and report on the live tick: the run's lengths are tabled once (``_after``, shared by
        copies), then each call is a bisection and a few float operations.
        """
        table = self._after
        if table is None:
            if len(self.segs):
                lens = np.hypot(self.segs[:, 2], self.segs[:, 3])
                lasts = self.segs[:, 4].tolist()
            else:
                lens = np.hypot(*np.diff(self.path, axis=0).T) if self.n > 1 else np.zeros(0)
                lasts = []
            after = np.zeros(len(lens) + 1)
            after[:-1] = np.cumsum(lens[::-1])[::-1]
            table = self._after = (after.tolist(), lens.tolist(), lasts, self.end())
        after_l, lens_l, lasts, _end = table
        if not lasts:
            return after_l[min(self.cursor, self.n - 1)]
        leg = bisect.bisect_left(lasts, self.cursor)  # the first leg whose last index is at or past it
        first = lasts[leg - 1] if leg > 0 else 0.0
        share = (self.cursor - first) / max(lasts[leg] - first, 1.0)  # of the leg already passed
        return max(after_l[leg] - share * lens_l[leg], 0.0)

    def points(self) -> np.ndarray:
        """The path's points ``(K, 2)``, the same in either form."""
        if not len(self.segs):
            return self.path
        return _points(self.path, self.segs, self.n)

    def end(self) -> tuple[float, float]:
        """The path's last point."""
        x, y = _point(self.path, self.segs, self.n - 1)
        return float(x), float(y)

    def _track(self) -> tuple[np.ndarray, np.ndarray, int, int, int, int, float, bool, int]:
        """What the compiled kernels read of this run: its path (either form) and how far along it is."""
        return (
            self.path,
            self.segs,
            self.n,
            self.cursor,
            self.advisories,
            self.limit,
            self.step,
            self.to_goal,
            self.lead,
        )

    def then(self, other: EscapeRun | None) -> EscapeRun:
        """This run followed by ``other`` (which starts where this one ends)."""
        if other is None:
            return self
        name = f"{self.name}, then {other.name}"
        if len(self.segs) and len(other.segs):  # other's first point is this one's last: dropped
            tail = other.segs.copy()
            tail[:, 4] += self.n - 1
            run = EscapeRun(name, NO_POINTS, self.step, other.to_goal, segs=np.concatenate([self.segs, tail]))
            run.route = self.route  # a way out first: what the unit does now
            return run
        pts = np.concatenate([self.points(), other.points()[1:]])
        run = EscapeRun(name, pts, self.step, other.to_goal)
        run.route = self.route
        return run

    def ahead(self, unit: np.ndarray, x: float, y: float, steps: int) -> list[tuple[float, float]] | None:
        """The next ``steps`` positions of ``unit`` (``steprule.unit``) at ``(x, y)`` steering along this run.

        Exactly what a ghost stepper walks (``Stepper.advise`` then ``steer``
        each step, ``steprule.judge`` ending the track at the goal or the
        bounds), in one compiled loop, without moving this run's cursor.
        ``None`` when the run would end within those steps (its exit, or its
        advisory limit): plain descent takes over there, so walk a ghost.
        """
        out = np.empty((steps + 1, 2))
        n = _ahead(*self._track(), unit, x, y, steps, out, *self.zones.packed())
        if n < 0:
            return None
        return list(map(tuple, out[:n].tolist()))

    def direction(self, x: float, y: float) -> tuple[float, float] | None:
        """``(dx, dy)``: the heading towards the path ahead; ``None`` once at the exit (or abandoned)."""
        ok, self.cursor, self.advisories, dx, dy, self.off_m, self.ahead_m = _steer(*self._track(), x, y)
        return (dx, dy) if ok else None

    def steer(
        self, unit: np.ndarray, x: float, y: float, zones: ZoneSet | None = None
    ) -> tuple[float, float, float, float, float, float] | None:
        """``direction``, judged as a step of ``unit`` (``steprule.judge``): ``(dx, dy, dist, move, to_x, to_y)``.

        The step ends on the goal when it is within one step (the final
        approach).  ``None`` at the exit (or abandoned), and where the unit
        is not to move on (the stepper judged arrival and bounds before).
        Among keep-out ``zones``, a step that would cut a corner of the run
        into one heads for the run's next point instead (``_zone_heading``).
        """
        if zones is not None:
            self.zones = zones
        ok, self.cursor, self.advisories, code, dx, dy, dist, move, tx, ty, self.off_m, self.ahead_m = (
            _steer_step(*self._track(), unit, x, y, *self.zones.packed())
        )
        return (dx, dy, dist, move, tx, ty) if ok and code == steprule.GO else None


NO_POINTS = np.empty((0, 2))
NO_POINTS.flags.writeable = False
_NO_SEGS = np.empty((0, 5))
_NO_SEGS.flags.writeable = False


def path_length(corners: np.ndarray) -> float:
    """The length of the polyline ``corners`` ``(K, 2)``, metres."""
    seg = np.diff(corners, axis=0)
    return float(np.hypot(seg[:, 0], seg[:, 1]).sum())


def legs(corners: np.ndarray, step: float) -> np.ndarray:
    """``EscapeRun.segs`` for ``grid.resample(corners, step)``: each leg's start, delta and last index.

    The leg counts are ``resample``'s own (``grid.pieces``), so ``_point`` gives its points bit for bit.
    A single corner is one leg of no length (its one point, twice): callers
    pass routes of at least two.
    """
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 2:
        pts = np.concatenate([pts, pts])
    seg, k = pieces(pts, step)
    out = np.empty((len(seg), 5))
    out[:, :2] = pts[:-1]
    out[:, 2:4] = seg
    out[:, 4] = np.cumsum(k)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _leg(segs: np.ndarray, i: int) -> int:
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
    """Point ``i`` of a run kept as legs, on its leg ``leg`` (``_leg``)."""
    if i == 0:
        return segs[0, 0], segs[0, 1]
    first = segs[leg - 1, 4] if leg > 0 else 0.0
    t = (i - first) / (segs[leg, 4] - first)  # j / m, as grid.resample divides them
    return segs[leg, 0] + t * segs[leg, 2], segs[leg, 1] + t * segs[leg, 3]


@numba.njit(cache=True, nogil=True, inline="always")
def _point(path: np.ndarray, segs: np.ndarray, i: int) -> tuple[float, float]:
    """Point ``i`` of a run's path, in either form (``EscapeRun``)."""
    if segs.shape[0] == 0:
        return path[i, 0], path[i, 1]
    return _on_leg(segs, _leg(segs, i), i)


@numba.njit(cache=True, nogil=True)
def _points(path: np.ndarray, segs: np.ndarray, n: int) -> np.ndarray:
    out = np.empty((n, 2))
    for i in range(n):
        out[i, 0], out[i, 1] = _point(path, segs, i)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _steer(
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
    leg = _leg(segs, cursor) if legs else 0  # then walked along the window
    cx, cy = _point(path, segs, cursor)
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
    lx, ly = _point(path, segs, n - 1)
    if i >= n - 2 and math.hypot(lx - x, ly - y) <= step and not to_goal:
        return False, i, advisories, 0.0, 0.0, off, 0.0
    k = _pursuit(path, segs, n, i, lead, step)
    tx, ty = _point(path, segs, k)
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
    ax, ay = _point(path, segs, i)
    while k > low:
        bx, by = _point(path, segs, k)
        cx = bx - ax
        cy = by - ay
        norm = math.hypot(cx, cy)
        ok = True
        for j in range(i + 1, k):
            px, py = _point(path, segs, j)
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
def _steer_step(
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
    """``EscapeRun.steer``: ``_steer``, then the heading judged as a step (``steprule.judge``)."""
    ok, cursor, advisories, hx, hy, off, ahead = _steer(
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
        px, py = _point(path, segs, k)
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
def _ahead(
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
        ok, cursor, advisories, hx, hy, _off, _ahead = _steer(
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


def descent_route(sim: Foresight, goal: tuple[float, float]) -> tuple[EscapeRun | None, str]:
    """The foreseen descent (``sim``, with its path) as a route to track, and why it ends short, if it does.

    Its legs keep within ``tracking.SIMPLIFY_STEPS`` steps of the simulated
    descent, at the resolution simulated.  A descent foreseen trapped (or out
    of bounds) ends there, with the reason the stepper judges the unit
    trapped by when it gets there; one cut short by the simulation's budget
    ends where it got, to be chosen again there.
    """
    assert sim.path is not None
    if len(sim.path) < 2:
        return None, ""
    corners = simplify(sim.path, SIMPLIFY_STEPS * sim.step)
    arrives = sim.outcome is Outcome.ARRIVES
    if arrives and (corners[-1, 0], corners[-1, 1]) != goal:
        corners = np.concatenate([corners, np.array([goal])])
    run = EscapeRun.along("descent", corners, sim.step, to_goal=arrives)
    run.route = Route.DESCENT
    run.limit = NO_LIMIT
    ends = f"{sim.outcome.value.replace('_', ' ')} foreseen where descent stalls" if sim.outcome.fails else ""
    return run, ends
