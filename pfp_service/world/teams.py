"""The roles of a team as verdicts on one unit's step: ``lead``, ``follow`` and the controller ``link``.

Each role takes where the unit is, where its planned step would take it
(``to``: the end of the direction's reach) and what the role needs to know of
the others, and returns a ``Verdict``: go (the step as planned), hold (with
the reason), or a modified step (a nearer end on the same line, or another
point to make for, with the reason).  Pure functions of numbers: the world's
team book (``team_book``) gathers the positions and tracks and applies what
they say.  A verdict is never an exception: a step too short to judge goes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from itertools import chain
from typing import Literal, Protocol

import numpy as np

from pfp_service.core import polyline_kernels as kernels
from pfp_service.world import corridor
from pfp_service.world.polyline import Polyline, length, point_at, project
from pfp_service.world.polyline import dist as _dist

__all__ = [
    "GO",
    "SIGHT_CLEARANCE_M",
    "STANDOFF_TOLERANCE",
    "Polyline",
    "Sight",
    "Verdict",
    "control",
    "follow",
    "in_link",
    "lead",
    "leads",
    "length",
    "link",
    "point_at",
    "project",
]

Point = tuple[float, float]


class Sight(Protocol):
    """Whether two points see each other over the ground (a mast at each end), the sight line clearing
    it by ``clearance_m``; ``None`` where there is no terrain.  One with a ``resolution_m`` (the ground's
    cell) is asked along a step every half of it at most, not finer.  A link's is asked with the
    controller's point first and the robot's second: each end stands at its own unit's height
    (``team_masts``)."""

    def __call__(self, a: Point, b: Point, clearance_m: float = 0.0) -> bool: ...


# A robot's step keeps its sight line this far above the ground, where the link itself needs none: the
# controller's own next step then does not put a robot stopped at the edge of its sight in the shadow.
SIGHT_CLEARANCE_M = 1.0
# The lead waits once it is this share of its standoff further ahead than asked (the issue's ±25 %).
STANDOFF_TOLERANCE = 0.25
# A step is judged at points this far apart at most (a fraction of the distance kept, so a corridor or a
# radio range is never stepped over), and at no more than this many points.
_SAMPLES_MAX = 64
_CLOSE_M = 1.0  # a point this close to where the unit is: it is there
# a step's ends this far inside every radio disc: its samples are too (``_within``), rounding aside
_DISC_MARGIN_M = 1e-6
_ONE_BY_ONE = 4  # ``leads`` asks this many routes or fewer one at a time, more in one call
# A follower is kept this share of the corridor's half-width inside its edge: a step cut where it would
# leave ends on the edge itself, which a check of the track (rounding, another buffer) may put outside.
_EDGE_SHARE = 0.02


@dataclass(frozen=True, slots=True)
class Verdict:
    """What a role says of a unit's step: ``go``, ``hold`` (``reason``) or ``to`` another end (``reason``)."""

    kind: Literal["go", "hold", "to"]
    to: Point | None = None
    reason: str = ""


GO = Verdict("go")


def _hold(reason: str) -> Verdict:
    return Verdict("hold", None, reason)


def _kept(
    at: Point, to: Point, ok: Callable[[Point], bool], spacing_m: float, run_m: float | None = None
) -> float:
    """How much (0 to 1) of the step from ``at`` to ``to`` keeps ``ok`` from its start, judged every ``spacing_m``
    and where the unit stands at its next report (``run_m`` along it), wherever the samples fall."""
    far = _dist(at, to)
    n = min(_SAMPLES_MAX, max(1, math.ceil(far / spacing_m))) if spacing_m > 0.0 else 1
    fs = [k / n for k in range(1, n + 1)]
    if run_m is not None and 0.0 < run_m < far:
        fs = sorted({*fs, run_m / far})
    good = 0.0
    for f in fs:
        if not ok((at[0] + (to[0] - at[0]) * f, at[1] + (to[1] - at[1]) * f)):
            return good
        good = f
    return good


def _within(radio_range_m: float, ends: Sequence[Point], centres: Sequence[Point]) -> bool:
    """Whether both ``ends`` of a step lie within ``radio_range_m`` of every one of ``centres``, with
    ``_DISC_MARGIN_M`` to spare: then so does every point between them (a disc is convex, and the margin
    is far wider than the rounding of a sample's coordinates), so without terrain the step keeps every
    link ``_kept`` would sample along it.  A micro-optimisation (bench row: ``python -m
    benchmarks._march_world``, the judge's CPU): the samples are skipped, not changed."""
    inside = radio_range_m - _DISC_MARGIN_M
    hypot = math.hypot  # ``_dist(p, q)`` inlined, its very numbers: a loop, not a generator a pair
    for q in centres:
        for p in ends:
            if not hypot(q[0] - p[0], q[1] - p[1]) <= inside:
                return False
    return True


def _shortened(at: Point, to: Point, kept: float, reason: str) -> Verdict:
    """The step cut to the part kept: go when all of it is, hold when too little is."""
    if kept >= 1.0:
        return GO
    end = (at[0] + (to[0] - at[0]) * kept, at[1] + (to[1] - at[1]) * kept)
    if _dist(at, end) < _CLOSE_M:
        return _hold(reason)
    return Verdict("to", end, reason)


def lead(at: Point, route: Sequence[Point] | np.ndarray, standoff_m: float, main: str) -> Verdict:
    """The scout's step: make for the point ``standoff_m`` ahead of the main element along its route.

    Args:
        at: where the lead is.
        route: the main element's route from where it is (its first point) onward.
        standoff_m: how far ahead the lead keeps, metres along the route.
        main: the main element's id, for the reason.

    Returns:
        hold while the lead is at or past its place (saying it waits for the main element once it is
        more than ``STANDOFF_TOLERANCE`` further ahead than asked); else ``to`` its place on the route;
        go (its own way) once the main element's route left is no longer than the standoff.
    """
    return leads([(at, route, standoff_m, main)])[0]


def leads(asks: Sequence[tuple[Point, Sequence[Point] | np.ndarray, float, str]]) -> list[Verdict]:
    """``lead`` for each ``(at, route, standoff_m, main)``: every route's numbers in one compiled call
    (``polyline_kernels.places``), not a polyline made per lead.  A route is points, or their array
    ``(n, 2)`` (``team_leads.main_route``): the same numbers either way."""
    if len(asks) == 1 and isinstance(asks[0][1], np.ndarray) and len(asks[0][1]) > 1:
        # a live tick's one lead, as the loop below asks it (``polyline_kernels.place``), without the lists
        # made to sort a few asks.  A micro-optimisation (bench row: BENCHMARKS.md "The judge's members")
        at, route, standoff_m, main = asks[0]
        got1 = np.empty(4)
        pts1 = np.ascontiguousarray(route, dtype=float).reshape(-1, 2)
        kernels.place(pts1, float(at[0]), float(at[1]), float(standoff_m), got1)
        length, s, px, py = got1.tolist()
        return [_lead(at, standoff_m, main, length, s, (px, py))]
    out: list[Verdict] = [GO] * len(asks)
    many = [k for k, ask in enumerate(asks) if len(ask[1]) > 1]
    if len(many) <= _ONE_BY_ONE and all(isinstance(asks[k][1], np.ndarray) for k in many):
        # a route at a time (``polyline_kernels.place``, the same numbers): no arrays made to ask for a few.
        # A micro-optimisation (bench row: BENCHMARKS.md "A tick's fixed cost", the judge)
        for k in many:
            at, route, standoff_m, main = asks[k]
            got1 = np.empty(4)
            pts1 = np.ascontiguousarray(route, dtype=float).reshape(-1, 2)
            kernels.place(pts1, float(at[0]), float(at[1]), float(standoff_m), got1)
            length, s, px, py = got1.tolist()
            out[k] = _lead(at, standoff_m, main, length, s, (px, py))
        many = []
    if many:
        counts = [len(asks[k][1]) for k in many]
        routes = [asks[k][1] for k in many]
        if all(isinstance(r, np.ndarray) for r in routes):
            pts = np.concatenate(routes).astype(float, copy=False).reshape(-1, 2)
        else:  # flat iterators: a list of tuples made an array is NumPy's slow, general path
            flat = chain.from_iterable(p for r in routes for p in r)
            pts = np.fromiter(flat, dtype=float, count=2 * sum(counts)).reshape(-1, 2)
        first = np.zeros(len(many) + 1, dtype=np.intp)
        first[1:] = np.cumsum(counts)
        ats = np.fromiter(chain.from_iterable(asks[k][0] for k in many), dtype=float, count=2 * len(many))
        ats = ats.reshape(-1, 2)
        standoffs = np.fromiter((asks[k][2] for k in many), dtype=float, count=len(many))
        got = np.empty((len(many), 4))
        kernels.places(pts, first, ats, standoffs, got)
        for k, (length, s, px, py) in zip(many, got.tolist()):
            at, _, standoff_m, main = asks[k]
            out[k] = _lead(at, standoff_m, main, length, s, (px, py))
    for k, (at, route, standoff_m, main) in enumerate(asks):
        if len(route) > 1:
            continue
        if len(route) == 0:
            out[k] = _hold(f"no route of {main} to lead along")
            continue
        line = Polyline(route)  # one point: a line of no length
        out[k] = _lead(at, standoff_m, main, line.length, line.project(at)[0], line.point_at(standoff_m))
    return out


def _lead(at: Point, standoff_m: float, main: str, length: float, s: float, place: Point) -> Verdict:
    """``lead``'s verdict from its route's length, how far along it the lead projects (``s``) and its place
    (both read only when the route is longer than the standoff)."""
    if length <= standoff_m:  # the lead has cleared it all
        return GO  # ... so it goes its own way, not onto the main element's goal
    if s > standoff_m * (1.0 + STANDOFF_TOLERANCE):
        return _hold(f"waiting for {main}: {s:,.0f} m ahead along its route, standoff {standoff_m:,.0f} m")
    if s >= standoff_m - _CLOSE_M or _dist(at, place) < _CLOSE_M:  # at or past its place: never back
        return _hold(f"at its standoff {standoff_m:,.0f} m ahead of {main}")
    return Verdict("to", place, f"leading {main} by {standoff_m:,.0f} m along its route")


def follow(
    at: Point,
    to: Point,
    track: Sequence[Point] | Polyline,
    corridor_m: float,
    lead_id: str,
    lost: str,
    goal: Point | None = None,
) -> Verdict:
    """A follower's step: only onto ground the lead has crossed (its ``track`` buffered by ``corridor_m / 2``).

    Args:
        at: where the follower is.
        to: where its planned step ends.
        track: the lead's track, oldest first (or made a ``Polyline`` once, for all its followers).
        corridor_m: the cleared corridor's width.
        lead_id: the lead's id, for the reasons.
        lost: why the lead cannot be followed (lost, stopped), or ``""`` when it can.
        goal: the follower's goal, named in the hold at the end of the cleared ground when it lies
            off the corridor (the follower holds there until the lead clears ground to it, or its goal moves).

    Returns:
        hold when the lead is lost or stopped, or at the end of the cleared ground; the step cut short
        where it would leave the corridor; ``to`` a point of the track when the planned step leaves the
        corridor at once (along the track) or the follower is outside it (back onto it).
    """
    if lost:
        return _hold(f"holding: lead {lead_id} {lost}")
    if not track:
        return _hold(f"holding: lead {lead_id} has cleared no ground yet")
    half = corridor_m / 2.0 * (1.0 - _EDGE_SHARE)
    line = track if isinstance(track, Polyline) else Polyline(track)
    if len(line.pts) > 1:  # ``project`` and ``shared`` in one compiled call, their numbers
        s_at, off_at, both = kernels.project_shared(
            line.pts, line.ab, line.sq, line.seg, line.cum, at[0], at[1], to[0], to[1], half, half + 1e-6
        )
    else:
        s_at, off_at = line.project(at)
        both = None
    if off_at > half + 1e-6:  # outside (a step cut at its edge ends there, to rounding)
        nearest = line.point_at(s_at)
        return Verdict("to", nearest, f"back into the corridor {lead_id} cleared")
    if both if both is not None else line.shared(at, to, half):
        return GO  # both ends within one segment's stadium, which is convex: the whole step is
    room = corridor.near(line.pts, half, at, max(_dist(at, to), _CLOSE_M))
    kept = room.kept(at, to)
    if kept >= 1.0:
        return GO
    s_goal, off_goal = line.project(goal) if goal is not None else (0.0, 0.0)
    # its goal off the cleared ground, and the lead's track past it (not heading there): to the nearest of it
    if off_goal > half + _CLOSE_M and s_goal < line.length - _CLOSE_M:
        return _nearest_goal(line, half, at, s_at, s_goal, _dist(at, to), lead_id, off_goal - half)
    cut = (at[0] + (to[0] - at[0]) * kept, at[1] + (to[1] - at[1]) * kept)
    # a step cut short that would take it back along the track is not taken: pressed against the
    # corridor's edge by its planner (a threat beside the track), it would go back and forth
    if _dist(at, to) * kept >= _CLOSE_M and line.project(cut)[0] >= s_at - _CLOSE_M:
        return _shortened(at, to, kept, f"kept to the corridor {lead_id} cleared")
    cleared = line.length
    if s_at >= cleared - _CLOSE_M:  # never back along it
        return _at_end(line, half, lead_id, goal)
    ahead = max(_dist(at, to), _CLOSE_M)
    while (
        ahead >= _CLOSE_M
    ):  # a point of the track ahead, the straight way to it inside (a bend's chord is not)
        along = line.point_at(s_at + ahead)
        if _dist(at, along) >= _CLOSE_M and room.kept(at, along) >= 1.0:
            return Verdict("to", along, f"along the corridor {lead_id} cleared")
        ahead /= 2.0
    return _at_end(line, half, lead_id, goal)


def _at_end(line: Polyline, half: float, lead_id: str, goal: Point | None) -> Verdict:
    """The hold at the end of the cleared ground (naming its goal, when that lies off the ground)."""
    off = line.project(goal)[1] - half if goal is not None else 0.0
    if off > _CLOSE_M:
        return _hold(f"at the end of the ground {lead_id} has cleared: {_off_goal(lead_id, off)}")
    return _hold(f"at the end of the ground {lead_id} has cleared")


def _off_goal(lead_id: str, off: float) -> str:
    return f"its goal lies {off:,.0f} m off the ground {lead_id} cleared (give the team a goal, or move it)"


def _nearest_goal(
    line: Polyline,
    half: float,
    at: Point,
    s_at: float,
    s_goal: float,
    step: float,
    lead_id: str,
    off: float,
) -> Verdict:
    """A follower whose goal lies off the cleared ground goes along the track to the point nearest its
    goal and holds there, saying so: it never enters ground its lead has not crossed, and does not
    dither between its planner's pull and the corridor.  It goes on once the lead clears ground
    nearer its goal, or its goal moves."""
    why = _off_goal(lead_id, off)
    if abs(s_goal - s_at) < _CLOSE_M:
        return _hold(f"at the cleared ground nearest its goal: {why}")
    sign = 1.0 if s_goal > s_at else -1.0
    ahead = max(min(step, abs(s_goal - s_at)), _CLOSE_M)
    room = corridor.near(line.pts, half, at, ahead + _CLOSE_M)
    while ahead >= _CLOSE_M:
        p = line.point_at(s_at + sign * ahead)
        if _dist(at, p) >= _CLOSE_M and room.kept(at, p) >= 1.0:
            return Verdict("to", p, f"to the cleared ground nearest its goal: {why}")
        ahead /= 2.0
    return _hold(f"at the cleared ground nearest its goal: {why}")


def in_link(
    a: Point, b: Point, radio_range_m: float, sight: Sight | None = None, clearance_m: float = 0.0
) -> bool:
    """Whether units at ``a`` and ``b`` are linked: within ``radio_range_m``, and in sight where there is terrain."""
    return _dist(a, b) <= radio_range_m and (sight is None or sight(a, b, clearance_m))


def link(
    at: Point,
    to: Point,
    controller_at: Point | None,
    radio_range_m: float,
    controller: str,
    lost: str,
    sight: Sight | None = None,
    controller_next: Point | None = None,
    back: Sequence[Point] = (),
    run_m: float | None = None,
) -> Verdict:
    """A robot's step: within ``radio_range_m`` of its controller, and in its sight where there is terrain.

    Args:
        at: where the robot is.
        to: where its planned step ends.
        controller_at: where the controller is (``None``: unknown).
        radio_range_m: the controller's radio reach.
        controller: the controller's id, for the reasons.
        lost: why the controller cannot be kept to (lost, stopped), or ``""``.
        sight: whether two points see each other over the ground; ``None`` without terrain.
        controller_next: where the controller's own direction takes it by the next report, if known:
            both move at once, so a step is judged against it too, when holding keeps the link to it
            (when it does not, the controller's step is its own to judge: ``control``).
        back: the breadcrumbs, the robot's own track back to where its link last held (that point
            first): a robot out of link retraces it, newest first, rather than cut across unknown
            ground straight at its controller.
        run_m: how far along its step the robot will be at its next report, if known: that point is
            judged too (the samples along a long step are half a cell apart).

    Returns:
        hold when the controller is lost or stopped, or the step would break the link at once; the step
        cut short where it would; when the link is already broken, ``to`` the newest breadcrumb (back
        along its track), or to the controller (turning back) when it has none.
    """
    if lost or controller_at is None:
        return _hold(f"lost link: controller {controller} {lost or 'has no position'}")
    c = controller_at

    def linked(p: Point, clearance_m: float = 0.0) -> bool:
        return in_link(c, p, radio_range_m, sight, clearance_m)

    # without terrain ``linked(at)`` inlined, its very numbers: a robot's step is judged per report (a
    # micro-optimisation, bench row: BENCHMARKS.md "The judge's members", the judge)
    here = math.hypot(at[0] - c[0], at[1] - c[1]) <= radio_range_m if sight is None else linked(at)
    if not here:
        far = _dist(at, c)
        why = (
            f"{far:,.0f} m from {controller}, radio range {radio_range_m:,.0f} m"
            if far > radio_range_m
            else f"out of {controller}'s line of sight"
        )
        crumb = next((p for p in reversed(back) if _dist(at, p) >= _CLOSE_M), None)
        if crumb is not None:
            return Verdict("to", crumb, f"lost link ({why}): back along its track to where the link held")
        return Verdict("to", c, f"lost link ({why}): turning back")
    n = controller_next
    if n is not None and (
        _dist(n, c) < _CLOSE_M or not in_link(n, at, radio_range_m, sight, SIGHT_CLEARANCE_M)
    ):
        n = None  # not moving, or out of its sight however the robot holds: judged where it is

    if sight is None and _within(radio_range_m, (at, to), (c,) if n is None else (c, n)):
        return GO  # every sample of the step is in both discs (``_within``): ``_kept`` would keep it all

    def kept_by_both(p: Point) -> bool:
        return linked(p, SIGHT_CLEARANCE_M) and (
            n is None or in_link(n, p, radio_range_m, sight, SIGHT_CLEARANCE_M)
        )

    # a disc is left once, so the range alone is judged coarsely; a ridge's shadow may be narrow, but
    # not narrower than the ground's resolution shows (each sight line costs a profile of the DEM)
    spacing = (
        max(radio_range_m / 16.0, _CLOSE_M)
        if sight is None
        else max(_dist(at, to) / _SAMPLES_MAX, getattr(sight, "resolution_m", 0.0) / 2.0)
    )
    kept = _kept(at, to, kept_by_both, spacing, run_m)
    beyond = (
        f"{_dist(to, c):,.0f} m from {controller}, radio range {radio_range_m:,.0f} m"
        if _dist(to, c) > radio_range_m
        else f"out of {controller}'s line of sight"
    )
    if n is not None and linked(to, SIGHT_CLEARANCE_M):
        beyond = f"out of link with where {controller}'s own step takes it"
    return _shortened(at, to, kept, f"the step would break the link to {controller} ({beyond})")


def control(
    at: Point,
    to: Point,
    robots: Sequence[tuple[str, Point]],
    radio_range_m: float,
    sight: Sight | None = None,
    next_of: Mapping[str, Point] | None = None,
    run_m: float | None = None,
    sights: Mapping[str, Sight] | None = None,
) -> tuple[Verdict, str]:
    """A controller's step: it keeps each of its robots it is linked to in range and, over terrain, in sight.

    A robot's own step keeps its sight line ``SIGHT_CLEARANCE_M`` clear (``link``); the controller's is
    judged with none, so a robot stopped at the edge of its sight does not stop its controller at once.

    Args:
        at: where the controller is.
        to: where its planned step ends.
        robots: ``(id, where)`` of each robot it keeps a link to (those it has lost turn back on their own).
        radio_range_m: its radio's reach.
        sight: whether two points see each other over the ground; ``None`` without terrain.
        next_of: where a robot's own direction takes it by the next report, if known: both move at once,
            so the step keeps that point linked too, when holding does.
        run_m: how far along its step the controller will be at its next report, if known: judged too.
        sights: a robot's own sight line (each end at its unit's height: ``team_masts``), over ``sight``.

    Returns:
        ``(verdict, robot)``: go; the step cut short where it would break a robot's link (``robot`` that
        one); hold when it would at once.
    """

    def linked(p: Point, rid: str, r: Point) -> bool:
        return in_link(p, r, radio_range_m, sights.get(rid, sight) if sights else sight)

    ahead = next_of or {}
    if sight is None and not sights:  # ``linked`` and ``_dist`` inlined, their very numbers (as ``link``'s)
        hypot = math.hypot
        kept = [(rid, r) for rid, r in robots if hypot(r[0] - at[0], r[1] - at[1]) <= radio_range_m]
        kept += [
            (rid, n)
            for rid, r in kept
            if (n := ahead.get(rid)) is not None
            and hypot(r[0] - n[0], r[1] - n[1]) >= _CLOSE_M
            and hypot(n[0] - at[0], n[1] - at[1]) <= radio_range_m
        ]
    else:
        kept = [(rid, r) for rid, r in robots if linked(at, rid, r)]
        kept += [
            (rid, n)
            for rid, r in kept
            if (n := ahead.get(rid)) is not None and _dist(n, r) >= _CLOSE_M and linked(at, rid, n)
        ]
    if not kept or (
        sight is None and not sights and _within(radio_range_m, (at, to), [r for _, r in kept])
    ):  # no link to keep, or (no sight line to ask) every sample of the step keeps them all (``_within``)
        return GO, ""
    spacing = (
        max(radio_range_m / 16.0, _CLOSE_M)
        if sight is None
        else max(_dist(at, to) / _SAMPLES_MAX, getattr(sight, "resolution_m", 0.0) / 2.0)
    )
    broken = [""]

    def ok(p: Point) -> bool:
        for rid, r in kept:
            if not linked(p, rid, r):
                broken[0] = rid
                return False
        return True

    got = _kept(at, to, ok, spacing, run_m)
    if got >= 1.0:
        return GO, ""
    return _shortened(at, to, got, f"the step would break {broken[0]}'s link"), broken[0]
