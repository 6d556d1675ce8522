"""Trap escape for one unit: choose a way out, judge it, then steer along it.

The stepper hands a trap to its ``Escaper`` only after plain descent has
given its trapped verdict, so descent itself pays nothing for this module.

Choosing.  ``escape`` names one strategy (``escape_strategies.STRATEGIES``)
or ``auto``, which escalates tier by tier: it asks each strategy of the
cheapest tier (``delta, random, waypoint, contour``) for its first acceptable
candidate and commits to the one of least estimated
``J = length + LAMBDA * exposure`` to the goal (escape path, simulated descent
after it, straight remainder).  It pays for the next tier (``global``) when
none of them has one, or when the best costs more than ``1 + AUTO_MARGIN``
times the straight line to the goal; a dearer candidate wins only when it is
cheaper by more than ``AUTO_MARGIN`` (5 %).  A single named strategy commits
to its own first acceptable candidate.  A goal inside a threat core is
refused at once, with a reason naming the threat.  Every candidate is *judged* before
the unit moves:

1. it may not enter a threat core (``cores``) nor leave the mission bounds;
2. simulated plain descent from its exit may not enter a core either, and
   must reach the goal or end clearly closer to it than the trap was
   (``margin = max(4 step, 5 % of the trap distance)``).

This is what makes ``auto`` refuse to raise delta through a symmetric block:
that candidate enters the block's core, so the next strategy is asked.  A
strategy already used at the same trap (within ``max(10 step, margin)``) is
not asked again there.  When nothing passes, the verdict is ``trapped`` with
every strategy's reason; at most ``MAX_TRAPS`` escapes are made per goal.

Steering.  The committed path is followed by aiming two points ahead of the
nearest path point, found from the reported position, so a unit that drifts
a little still follows it.  The escape ends at the exit (or is abandoned
after ``2 * len(path) + 20`` advisories) and plain descent resumes, except
that a path ending within ``HANDOFF_STEPS`` steps of the goal is followed on
to the goal itself: near the goal a threat's gradient can be a hundred times
the goal's pull, and descent there would drift off a route that had arrived.

Randomness comes from ``numpy.random.default_rng([seed, unit_key, trap])``:
the same unit, seed and trap always make the same choice, live or preview.

Foreseen traps.  Under ``auto`` the stepper also simulates its own descent
when the goal is set and after each world change (``foresight``).  When that
simulation is trapped (or leaves the bounds), ``foresee`` commits at once to
the whole ``global`` route, judged like any candidate: a way round chosen
before the unit walks in, not after.  That route is the Dijkstra optimum of
``length + LAMBDA * exposure``, shortcut, so it lies near the
length/exposure Pareto front; the cheap strategies stay for traps that were
not foreseen (drift, or threats that appear later).  When the simulation
arrives instead, ``cheaper_route`` compares its ``J`` with the route's and
commits to the route only when it is cheaper by more than ``AUTO_MARGIN``
(descent down a channel between threats arrives, at a high price).  A unit
that starts inside a core first leaves it by the shortest straight way out
(``leave_core``; its escape is logged as ``leave core <id>``, or ``leave zone <id>``
for a keep-out zone, left past its nearest edge).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core import cull, steprule, zones
from pfp_service.core.cores import ZONE_PREFIX, Cores
from pfp_service.core.escape_strategies import (
    AUTO_ORDER,
    STRATEGIES,
    Bounds,
    NoCandidate,
    Trap,
    global_corners,
    rollout,
)
from pfp_service.core.grid import pieces, polyline_clear, resample
from pfp_service.core.metrics import LAMBDA, path_cost
from pfp_service.core.params import Resolved
from pfp_service.core.threat import ThreatField
from pfp_service.core.tracking import LEAD_STEPS, PURSUIT_TOLERANCE_STEPS, Route
from pfp_service.core.zones import ZoneSet

__all__ = ["AUTO_MARGIN", "AUTO_ORDER", "HANDOFF_STEPS", "MAX_TRAPS", "EscapeRun", "Escaper"]

MAX_TRAPS = 12
AUTO_MARGIN = 0.05  # "clearly cheaper": a dearer way is taken only when it saves more than 5 % of J
HANDOFF_STEPS = 4.0  # an escape ending this many steps from the goal steers on to it


_NO_ZONES = ZoneSet()


def route_cost(path: np.ndarray, field: ThreatField, lam: float = LAMBDA) -> float:
    """``metrics.path_cost`` of a way to rank, each level summed over its own cell of the field's index.

    Simpson on every segment, as ``path_cost``; among many threats each point
    sums only the threats its cell of ``cull.index_of(field)`` lists (off by
    at most the index's ``level_bound``), and each vertex is evaluated once.
    """
    index = cull.index_of(field)
    pts = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    if index is None or len(pts) < 2:
        return path_cost(pts, field, lam)
    mid = 0.5 * (pts[:-1] + pts[1:])
    lv = cull.cell_level(index, np.concatenate([pts, mid]))
    vert, half = lv[: len(pts)], lv[len(pts) :]
    seglen = np.hypot(*np.diff(pts, axis=0).T)
    exposure = float(np.sum(seglen * (vert[:-1] + 4.0 * half + vert[1:])) / 6.0)
    return float(seglen.sum()) + lam * exposure


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
            self.path = _NO_POINTS
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

    @classmethod
    def along(cls, name: str, corners: np.ndarray, step: float, to_goal: bool = False) -> EscapeRun:
        """The run along ``corners`` resampled at ``step`` (``grid.resample``), kept as its legs."""
        return cls(name, _NO_POINTS, step, to_goal, segs=legs(corners, step))

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
            return EscapeRun(
                name, _NO_POINTS, self.step, other.to_goal, segs=np.concatenate([self.segs, tail])
            )
        pts = np.concatenate([self.points(), other.points()[1:]])
        return EscapeRun(name, pts, self.step, other.to_goal)

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


_NO_POINTS = np.empty((0, 2))
_NO_POINTS.flags.writeable = False
_NO_SEGS = np.empty((0, 5))
_NO_SEGS.flags.writeable = False


def _length(corners: np.ndarray) -> float:
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


def _leaving(run: EscapeRun) -> EscapeRun:
    run.route = Route.LEAVE
    return run


class _Site:
    __slots__ = ("tried", "x", "y")

    def __init__(self, x: float, y: float) -> None:
        self.x, self.y = x, y
        self.tried: set[str] = set()


class Escaper:
    """The escape state of one unit for one goal: its traps and what was tried at each.

    Args:
        params: the stepper's resolved parameters (``escape`` must not be ``none``).
        goal, goal_gain: the stepper's goal and ``delta / ||goal - x0||^2``.
        bounds: the mission bounds, if any.
        unit_key: distinguishes units for the seeded random strategy.
    """

    def __init__(
        self,
        params: Resolved,
        goal: tuple[float, float],
        goal_gain: float,
        bounds: Bounds | None,
        unit_key: int,
    ) -> None:
        self.params = params
        self.goal = goal
        self.goal_gain = goal_gain
        self.bounds = bounds
        self.unit_key = unit_key
        self.traps = 0
        self.escape_steps = 0
        self.log: list[str] = []
        self._sites: list[_Site] = []

    def __deepcopy__(self, memo: dict[int, object]) -> Escaper:
        """A detached copy (deliberation, previews): the parameters and goal shared, the history copied."""
        new = Escaper.__new__(Escaper)
        new.__dict__.update(self.__dict__)
        new.log = list(self.log)
        new._sites = []
        for site in self._sites:
            twin = _Site(site.x, site.y)
            twin.tried = set(site.tried)
            new._sites.append(twin)
        return new

    def forget_sites(self) -> None:
        """The world changed: what failed at a trap before may work now."""
        self._sites.clear()

    def begin(self, field: ThreatField, x: float, y: float, reason: str) -> tuple[EscapeRun | None, str]:
        """Pick an escape from a trap at ``(x, y)``.

        Returns:
            ``(run, "")`` with the committed escape, or ``(None, why)`` when no
            candidate passes; ``why`` starts with the trap ``reason``.
        """
        self.traps += 1
        if self.traps > MAX_TRAPS:
            return None, f"{reason}; gave up after {MAX_TRAPS} escapes"
        trap = self._trap(field, x, y)
        inside = trap.cores.core_at(*self.goal)
        if inside:
            return None, f"{reason}; the goal lies in {Cores.region(inside)}, which no escape enters"
        site = self._site(x, y, max(10.0 * self.params.step, trap.margin))
        order = AUTO_ORDER if self.params.escape == "auto" else (self.params.escape,)
        refusals: list[str] = []
        best: tuple[float, str, np.ndarray] | None = None
        for name in order:
            tier = STRATEGIES[name].tier
            dearer = best is not None and tier > STRATEGIES[best[1]].tier
            if best is not None and dearer and best[0] <= (1.0 + AUTO_MARGIN) * trap.dist:
                break  # nothing can beat the straight line clearly: no need for a dearer tier
            if name in site.tried:
                refusals.append(f"{name}: already tried at this trap")
                continue
            found = self._first_pass(trap, name, refusals)
            if found is None:
                continue
            if best is None or found[0] * (1.0 + (AUTO_MARGIN if dearer else 0.0)) < best[0]:
                best = (found[0], name, found[1])
        if best is None:
            return None, f"{reason}; no escape found: " + "; ".join(refusals)
        _, name, path = best
        site.tried.add(name)
        self.log.append(name)
        return self._run(name, path, trap), ""

    def foresee(self, field: ThreatField, x: float, y: float, ahead: str) -> tuple[EscapeRun | None, str]:
        """Plain descent from ``(x, y)`` is foreseen to end ``ahead`` (``foresight``): go round now.

        Rather than walk into the trap and back out, commit to the whole
        ``global`` route to the goal, judged like any candidate.

        Returns:
            ``(run, "")``, or ``(None, why)`` when there is no acceptable route;
            the stepper then descends and meets the trap as usual.
        """
        self.traps += 1
        tr = self._trap(field, x, y)
        inside = tr.cores.core_at(*self.goal)
        if inside:
            return None, f"{ahead} foreseen; the goal lies in {Cores.region(inside)}"
        corners = global_corners(tr)
        if isinstance(corners, NoCandidate):
            return None, f"{ahead} foreseen; {corners.reason}"
        poly = resample(corners, tr.step)
        verdict, _ = self._judge(tr, poly)
        if verdict:
            return None, f"{ahead} foreseen; global: {verdict}"
        self.log.append("global")
        return self._run(f"global ({ahead} foreseen)", poly, tr, corners, Route.AROUND_TRAP), ""

    def cheaper_route(self, field: ThreatField, x: float, y: float, foreseen_cost: float) -> EscapeRun | None:
        """Plain descent from ``(x, y)`` is foreseen to arrive at ``J = foreseen_cost``: is going round clearly cheaper?

        The ``global`` route is searched only when the foreseen ``J`` exceeds
        the straight-line distance by more than ``AUTO_MARGIN`` (no route can
        beat it by more otherwise), and committed to only when its own ``J``
        is lower by more than ``AUTO_MARGIN``, and it passes the judge.
        """
        dist = math.hypot(self.goal[0] - x, self.goal[1] - y)
        if not foreseen_cost > (1.0 + AUTO_MARGIN) * dist:
            return None
        tr = self._trap(field, x, y)
        if tr.cores.core_at(*self.goal):
            return None
        corners = global_corners(tr)
        if isinstance(corners, NoCandidate):
            return None
        if _length(corners) * (1.0 + AUTO_MARGIN) >= foreseen_cost:
            return None  # its J is at least its length (exposure is never negative): no need to price it
        poly = resample(corners, tr.step)
        if self._judge(tr, poly)[0] or route_cost(poly, field) * (1.0 + AUTO_MARGIN) >= foreseen_cost:
            return None
        self.log.append("global")
        return self._run("global (cheaper than descent)", poly, tr, corners, Route.LOWER_EXPOSURE)

    def leave_core(self, field: ThreatField, x: float, y: float) -> EscapeRun | None:
        """``None`` unless ``(x, y)`` lies in a threat core; then the shortest straight way out of every core."""
        cores = Cores.of(field)
        inside = cores.core_at(x, y)
        if not inside:
            return None
        p = self.params
        if inside.startswith(ZONE_PREFIX):  # a zone's shortest way out is exact: past its nearest edge
            zone = inside[len(ZONE_PREFIX) :]
            end = cores.zones.way_out(x, y, p.step)
            if end is None:
                return None
            self.log.append(f"leave zone {zone}")
            return _leaving(EscapeRun.along(f"leave zone {zone}", np.array([(x, y), end]), p.step))
        spacing = min(p.step, cores.min_spread_m / 4.0)
        reach = 6.0 * max(t.spread() for t in field.threats)
        n = min(2000, math.ceil(reach / spacing))
        angles = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
        d = np.arange(1, n + 1) * (reach / n)
        rays = np.stack([x + np.sin(angles)[:, None] * d, y + np.cos(angles)[:, None] * d], axis=-1)
        blocked = cores.inside(rays.reshape(-1, 2)).reshape(len(angles), n)
        out = np.where(blocked.all(axis=1), n, np.argmin(blocked, axis=1))
        k = int(np.argmin(out))
        if out[k] >= n:
            return None  # no straight way out within reach: descend as usual
        r = d[min(out[k], n - 1)] + p.step  # one step clear of the core's edge
        end = (x + math.sin(angles[k]) * r, y + math.cos(angles[k]) * r)
        self.log.append(f"leave core {inside}")
        return _leaving(
            EscapeRun.along(f"leave the core of threat {inside}", np.array([(x, y), end]), p.step)
        )

    def _run(
        self,
        name: str,
        path: np.ndarray,
        tr: Trap,
        corners: np.ndarray | None = None,
        route: Route = Route.ESCAPE,
    ) -> EscapeRun:
        """The run for a committed path; one ending near the goal goes on to it (``EscapeRun.to_goal``).

        ``corners``: ``path`` is ``resample(corners, step)``, and the run keeps only its legs.
        ``route``: what the run is, for the direction.
        """
        run = self._made(name, path, tr, corners)
        run.route = route
        return run

    def _made(self, name: str, path: np.ndarray, tr: Trap, corners: np.ndarray | None) -> EscapeRun:
        gx, gy = self.goal
        ex, ey = path[-1]
        near = math.hypot(gx - ex, gy - ey) <= HANDOFF_STEPS * tr.step
        to_goal = bool(near and not tr.cores.first_hit(np.array([(ex, ey), (gx, gy)])))
        tail = np.array([(ex, ey), (gx, gy)]) if to_goal and (ex, ey) != (gx, gy) else None
        if corners is None:
            if tail is not None:
                path = np.concatenate([path, resample(tail, tr.step)[1:]])
            return EscapeRun(name, path, tr.step, to_goal)
        segs = legs(corners, tr.step)
        if tail is not None:
            more = legs(tail, tr.step)
            more[:, 4] += segs[-1, 4]
            segs = np.concatenate([segs, more])
        return EscapeRun(name, _NO_POINTS, tr.step, to_goal, segs=segs)

    def _trap(self, field: ThreatField, x: float, y: float) -> Trap:
        p = self.params
        dist = math.hypot(self.goal[0] - x, self.goal[1] - y)
        return Trap(
            field=field,
            cores=Cores.of(field),
            x=x,
            y=y,
            goal=self.goal,
            delta=p.delta,
            gain=self.goal_gain,
            step=p.step,
            tolerance=p.tolerance,
            trap_window=p.trap_window,
            dist=dist,
            margin=max(4.0 * p.step, 0.05 * dist),
            budget=int(min(8000, max(10 * p.trap_window, math.ceil(min(6.0 * dist / p.step, 8000.0))))),
            bounds=self.bounds,
            rng=np.random.default_rng([p.seed & 0xFFFFFFFF, self.unit_key & 0xFFFFFFFF, self.traps]),
            unit_key=self.unit_key,
        )

    def _first_pass(self, tr: Trap, name: str, refusals: list[str]) -> tuple[float, np.ndarray] | None:
        """The first candidate of strategy ``name`` that passes, with its estimated cost to the goal."""
        why, n = "", 0
        for cand in STRATEGIES[name].propose(tr):
            if isinstance(cand, NoCandidate):
                why = why or cand.reason
                break
            n += 1
            verdict, after = self._judge(tr, cand)
            if not verdict:
                return self._cost(tr, cand, after), cand
            why = why or verdict
        refusals.append(f"{name}: {why or 'no candidate'}" + (f" ({n} candidates refused)" if n > 1 else ""))
        return None

    @staticmethod
    def _cost(tr: Trap, poly: np.ndarray, after: np.ndarray) -> float:
        """``J`` of the escape, the descent after it, and the straight remainder to the goal."""
        pts = np.concatenate([poly, after[1:]])
        rest = math.hypot(tr.goal[0] - pts[-1, 0], tr.goal[1] - pts[-1, 1])
        return route_cost(pts, tr.field) + rest

    def _site(self, x: float, y: float, radius: float) -> _Site:
        for s in self._sites:
            if math.hypot(s.x - x, s.y - y) <= radius:
                return s
        s = _Site(x, y)
        self._sites.append(s)
        return s

    def _judge(self, tr: Trap, poly: np.ndarray) -> tuple[str, np.ndarray]:
        """``("", descent after it)`` if the candidate is acceptable, else ``(why not, ...)``."""
        none = poly[-1:]
        if len(poly) < 2:
            return "goes nowhere", none
        if self.bounds is not None:
            (x0, y0), (x1, y1) = self.bounds
            if np.any((poly[:, 0] < x0) | (poly[:, 0] > x1) | (poly[:, 1] < y0) | (poly[:, 1] > y1)):
                return "leaves the mission bounds", none
        hit = "" if polyline_clear(tr.cores, poly) else tr.cores.first_hit(poly)
        if hit:
            return f"passes through {Cores.region(hit)}", none
        end = (float(poly[-1, 0]), float(poly[-1, 1]))
        n = int(min(20000, math.ceil(3.0 * tr.dist / tr.step) + 4 * tr.trap_window))
        after = rollout(tr.field, end, tr.goal, tr.gain, tr.step, tr.tolerance, n)
        hit = "" if polyline_clear(tr.cores, after) else tr.cores.first_hit(after)
        if hit:
            return f"descent after it passes through {Cores.region(hit)}", after
        d_end = math.hypot(tr.goal[0] - after[-1, 0], tr.goal[1] - after[-1, 1])
        if d_end > tr.tolerance and d_end > tr.dist - tr.margin:
            return "descent after it ends no closer to the goal", after
        return "", after
