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
from typing import Any

import numpy as np

from pfp_service.core import steprule
from pfp_service.core.advice import StepStatus
from pfp_service.core.foresight import Foresight, Outcome
from pfp_service.core.polylines import pieces
from pfp_service.core.route_kernels import ahead_walk, point_of, points_of, steer_step, steer_to
from pfp_service.core.tracking import LEAD_STEPS, SIMPLIFY_STEPS, Route, simplify
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

    The path is kept in one of two forms, each read through ``point_of``:
    ``path``, its points ``(K, 2)``; or, for a route made of long straight
    legs (``along``: a global route, a way out of a core), ``segs``, one row
    ``(ax, ay, dx, dy, last)`` a leg, whose points are exactly those
    ``polylines.resample`` makes (``a + (j / m) d``, ``j = 1..m``; ``last`` the
    index of the leg's final point).  A 2 km route at a 1 m step is then a
    few hundred bytes instead of 30 KB, in the world's books and in every
    worker's answer.
    """

    __slots__ = (
        "_after",
        "_left",
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
        # ``left_to``'s answer at a cursor for a goal: it changes only when the cursor moves
        self._left: tuple[int, tuple[float, float] | None, float] = (-1, None, 0.0)

    def __setstate__(self, state: tuple[dict[str, Any] | None, dict[str, Any]]) -> None:
        """Unpickled (a route a deliberation worker found): its arrays read-only again, as made here.

        numba compiles a kernel per argument type, and a writable array is another type than a
        read-only one: a route from a worker would otherwise compile ``steer_step`` and
        ``ahead_walk`` afresh, in the live loop, the first time one is steered.
        """
        for name, value in state[1].items():
            object.__setattr__(self, name, value)
        self.path.flags.writeable = False
        self.segs.flags.writeable = False

    @classmethod
    def along(cls, name: str, corners: np.ndarray, step: float, to_goal: bool = False) -> EscapeRun:
        """The run along ``corners`` resampled at ``step`` (``polylines.resample``), kept as its legs."""
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

    def left_to(self, goal: tuple[float, float]) -> float:
        """Metres still to drive to ``goal``: the run from its cursor, then straight on from its end if it stops short.

        Per unit and report on the live tick, though the cursor moves only
        every few reports: kept for the cursor it was made at (and the goal,
        the same object report after report: its stepper's).
        """
        at, to, left = self._left
        if at == self.cursor and to is goal:
            return left
        left = self.left_m()
        if not self.to_goal:
            left += self.end_to(goal)
        self._left = (self.cursor, goal, left)
        return left

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
        return points_of(self.path, self.segs, self.n)

    def end(self) -> tuple[float, float]:
        """The path's last point."""
        x, y = point_of(self.path, self.segs, self.n - 1)
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
        out = self.ahead_points(unit, x, y, steps)
        return None if out is None else list(map(tuple, out.tolist()))

    def ahead_points(self, unit: np.ndarray, x: float, y: float, steps: int) -> np.ndarray | None:
        """``ahead``'s positions as an array ``(n, 2)``: for a caller that wants the numbers, not points."""
        out = np.empty((steps + 1, 2))
        n = ahead_walk(*self._track(), unit, x, y, steps, out, *self.zones.packed())
        return None if n < 0 else out[:n]

    def direction(self, x: float, y: float) -> tuple[float, float] | None:
        """``(dx, dy)``: the heading towards the path ahead; ``None`` once at the exit (or abandoned)."""
        ok, self.cursor, self.advisories, dx, dy, self.off_m, self.ahead_m = steer_to(*self._track(), x, y)
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
            steer_step(*self._track(), unit, x, y, *self.zones.packed())
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
    """``EscapeRun.segs`` for ``polylines.resample(corners, step)``: each leg's start, delta and last index.

    The leg counts are ``resample``'s own (``polylines.pieces``), so ``point_of`` gives its points bit for bit.
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
