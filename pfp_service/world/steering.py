"""The reactive step of the world: a batch of guided units advised at once, and their directions on the wire.

``steer`` advises every unit in one vectorised call (culled, ``core.cull``)
and predicts their look-ahead in one more.  Bulkheads: if a unit's numbers
break a batch, it is run again one unit at a time, and a unit that fails
alone, or whose direction is not finite, is handed back as a failure; every
other unit is steered.  ``direction`` turns one unit's advice into its
``Direction`` and, on a change of status, its ``arrived`` or ``trapped``
event, with the verdict the unit's owner keeps on its record
(``units.Units.steered``).  Pure values in and out: nothing here writes a record.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from collections.abc import Sequence

import msgspec
import numpy as np

from pfp_service.core import StepStatus, ThreatField
from pfp_service.core.advice import Advice
from pfp_service.core.batch import advise_many
from pfp_service.core.cull import CullIndex
from pfp_service.core.tracking import PURSUIT_TOLERANCE_STEPS, Route
from pfp_service.errors import FINITE_LIMIT, InputError
from pfp_service.geo import Origin
from pfp_service.wire import (
    ArrivedEvent,
    Direction,
    DirectionStatus,
    Event,
    RejectedEvent,
    ReplanEvent,
    RouteKind,
    ThreatChange,
    TrappedEvent,
)
from pfp_service.wire.geodetic import with_geodetic_many
from pfp_service.wire.messages import MAX_EVENT_ITEMS
from pfp_service.world.dispersion import Dispersion
from pfp_service.world.lookahead import Track, lookahead, within_map
from pfp_service.world.units import NO_GOAL, UnitRecord, Verdict

__all__ = [
    "NO_GOAL",
    "STATUS",
    "advise",
    "ahead",
    "direction",
    "geodetic",
    "no_goal",
    "rejected",
    "replan",
    "steer",
]

STATUS = {
    StepStatus.EN_ROUTE: DirectionStatus.EN_ROUTE,
    StepStatus.ESCAPING: DirectionStatus.ESCAPING,
    StepStatus.ARRIVED: DirectionStatus.ARRIVED,
    StepStatus.TRAPPED: DirectionStatus.TRAPPED,
    # mission bounds are enforced on decode; a stepper verdict of these is a dead end all the same
    StepStatus.OUT_OF_BOUNDS: DirectionStatus.TRAPPED,
    StepStatus.INVALID: DirectionStatus.TRAPPED,
}

Steered = list[tuple[UnitRecord, Advice, Track]]
_ROUTE_KIND = {r: RouteKind(r.value) for r in Route}  # the core's names on the wire, looked up once
Failed = list[tuple[UnitRecord, BaseException]]


def steer(
    guided: list[UnitRecord], fld: ThreatField, cull: CullIndex | None, n: int, disp: Dispersion | None = None
) -> tuple[Steered, Failed]:
    """Advise the units (each with a stepper and a position) and predict ``n`` positions ahead.

    ``disp``: the world's dispersion, whose push each unit descends with the field (``advise``).

    Returns:
        (unit, advice, look-ahead) for each unit steered, in the order given,
        and (unit, error) for each unit that failed alone.
    """
    advised, failed = advise(guided, fld, cull, disp)
    steered, lost = ahead(advised, fld, cull, n)
    return steered, failed + lost


def advise(
    guided: list[UnitRecord], fld: ThreatField, cull: CullIndex | None, disp: Dispersion | None = None
) -> tuple[list[tuple[UnitRecord, Advice]], Failed]:
    """Advise the units (each with a stepper and a position): the first half of ``steer``, no look-ahead.

    With ``disp`` (on), each unit descends the field plus its neighbours'
    repulsion (``Dispersion.push``, ``advise_many``'s ``push``).

    Returns:
        (unit, advice) for each unit advised, in the order given, and (unit,
        error) for each unit that failed alone or whose direction is not finite.
    """
    failed: Failed = []
    push = disp.push(guided) if disp is not None else None
    try:
        advices = _advise(guided, fld, cull, push)
    except Exception:  # one unit's numbers broke the batch: each alone, the poisoned dropped
        advices, alone, guided = [], guided, []
        for k, rec in enumerate(alone):
            try:
                advices += _advise([rec], fld, cull, None if push is None else push[k : k + 1])
                guided.append(rec)
            except Exception as exc:
                failed.append((rec, exc))
    if not all(map(_finite, advices)):
        kept = []
        for rec, adv in zip(guided, advices):
            if _finite(adv):
                kept.append((rec, adv))
            else:
                failed.append((rec, FloatingPointError(f"a direction that is not finite at {rec.position}")))
        guided, advices = [r for r, _ in kept], [a for _, a in kept]
    return list(zip(guided, advices)), failed


def ahead(
    advised: list[tuple[UnitRecord, Advice]], fld: ThreatField, cull: CullIndex | None, n: int
) -> tuple[Steered, Failed]:
    """The ``n`` look-ahead points of units advised (``advise``): the second half of ``steer``.

    A wave's directions go out before this (``World``): the points are
    computed from the same advice once the directions are on their way.
    """
    failed: Failed = []
    guided, advices = [r for r, _ in advised], [a for _, a in advised]
    try:
        tracks = _ahead(guided, advices, fld, cull, n)
    except Exception:
        tracks, pairs, guided, advices = [], list(zip(guided, advices)), [], []
        for rec, adv in pairs:
            try:
                tracks += _ahead([rec], [adv], fld, cull, n)
                guided.append(rec)
                advices.append(adv)
            except Exception as exc:
                failed.append((rec, exc))
    if not _within(tracks):  # rare: some track leaves the map; each is cut where it does
        tracks = [within_map(t) for t in tracks]
    if not fld.zones:  # before its route lands, a unit's reach runs along its predicted descent
        advices = [_along_prediction(r, a, t) for r, a, t in zip(guided, advices, tracks)]
    return list(zip(guided, advices, tracks)), failed


def _along_prediction(rec: UnitRecord, adv: Advice, points: Track) -> Advice:
    if adv.route is not Route.NONE or not points or adv.status.terminal or rec.stepper is None:
        return adv
    assert rec.position is not None
    reach = _straight_reach(rec.position, adv.dx, adv.dy, adv.reach, points, rec.stepper.params.step)
    return adv if reach == adv.reach else adv._replace(reach=reach)


def _within(tracks: list[Track]) -> bool:
    """Whether every point of every track is on the wire's map (``within_map``), in one vectorised test."""
    flat = np.fromiter(itertools.chain.from_iterable(itertools.chain.from_iterable(tracks)), dtype=float)
    return bool(np.all(np.abs(flat) <= FINITE_LIMIT))  # NaN is not within


def _advise(
    guided: list[UnitRecord], fld: ThreatField, cull: CullIndex | None, push: np.ndarray | None
) -> list[Advice]:
    steppers = [r.stepper for r in guided]
    at = np.array([r.position for r in guided], dtype=float)
    return advise_many(steppers, fld, at, cull, push)  # type: ignore[arg-type]


def _ahead(
    guided: list[UnitRecord], advices: list[Advice], fld: ThreatField, cull: CullIndex | None, n: int
) -> list[Track]:
    return lookahead([r.stepper for r in guided], advices, fld, n, cull)  # type: ignore[misc]


def _finite(a: Advice) -> bool:
    return math.isfinite(a.dx + a.dy + a.level + a.distance)


def direction(
    rec: UnitRecord, adv: Advice, points: Track, planner: str, deliberating: bool
) -> tuple[Direction, Event | None, Verdict]:
    """The unit's direction for its advice, the event its change of status fires (if any), and its verdict."""
    assert rec.position is not None
    # called per unit of a wave: the advice unpacked once, and min/max spelt as the comparisons they make
    step_status, dx, dy, level, distance, why, asking, reach, _tx, _ty, route = adv
    status = STATUS[step_status]
    reason = why[:1024]
    event: Event | None = None
    if status is not rec.last_status:
        if status is DirectionStatus.ARRIVED:
            event = ArrivedEvent(
                planner=planner, unit=rec.id, position=rec.position, distance_to_goal=distance
            )
        elif status is DirectionStatus.TRAPPED:
            event = TrappedEvent(planner=planner, unit=rec.id, position=rec.position, reason=reason)
    terminal = step_status.terminal
    # min(distance, FINITE_LIMIT): the wire's bound, a diagonal of the map is more
    to_goal = FINITE_LIMIT if distance > FINITE_LIMIT else distance
    heading = None
    if not terminal and (dx or dy):
        heading = math.degrees(math.atan2(dx, dy)) % 360.0
        heading = 0.0 if heading >= 360.0 else heading  # -1e-300 % 360 is 360.0
    # min(max(level, 0.0), FINITE_LIMIT): the wire's bound, even for absurd weights
    low = 0.0 if level < 0.0 else level
    if not terminal and math.isfinite(reach):
        far = 0.0 if reach < 0.0 else reach
        reach_m: float | None = FINITE_LIMIT if far > FINITE_LIMIT else far
    else:
        reach_m = None
    # the metres of route the unit has still to drive, on the wire's map (not finite: none)
    left_m = None if terminal or rec.stepper is None else rec.stepper.route_left_m()
    if left_m is not None and not left_m <= FINITE_LIMIT:
        left_m = FINITE_LIMIT if left_m < math.inf else None
    d = Direction(
        unit=rec.id,
        seq=rec.seq,
        status=status,
        vector=(dx, dy),
        heading_deg=heading,
        distance_to_goal=to_goal,
        threat_level=FINITE_LIMIT if low > FINITE_LIMIT else low,
        lookahead=points,
        reason=reason,
        deliberating=asking or deliberating,
        planner=planner,
        reach_m=reach_m,
        route=_ROUTE_KIND[route],
        progress=rec.progress.verdict,
        route_left_m=left_m,
    )
    return d, event, Verdict(status, why, to_goal, None if terminal else (dx, dy))


def _straight_reach(
    at: tuple[float, float], dx: float, dy: float, reach: float, points: Track, step: float
) -> float:
    """Before a route lands: how far along ``(dx, dy)`` the predicted descent (``points``) stays beside it.

    The direction stays good as far as the look-ahead's points keep within
    ``tracking.PURSUIT_TOLERANCE_STEPS`` steps of its line; never less than
    the step judged (``reach``), nor more where that was cut short (the
    final approach).  Only where there are no keep-out zones (``ahead``).
    """
    if not reach >= step * 0.999:  # cut short of a zone, or the final approach: as judged
        return reach
    tol = PURSUIT_TOLERANCE_STEPS * step
    x0, y0 = at
    good = reach
    for px, py in points:
        along = (px - x0) * dx + (py - y0) * dy
        if abs((px - x0) * dy - (py - y0) * dx) > tol or along <= good - step:
            break
        good = max(good, along)
    return good


def no_goal(rec: UnitRecord, planner: str) -> Direction:
    """The direction of a unit with no goal: stand still (its verdict: ``NO_GOAL``)."""
    return Direction(
        unit=rec.id,
        seq=rec.seq,
        status=DirectionStatus.NO_GOAL,
        vector=(0.0, 0.0),
        planner=planner,
        reason=rec.goal_gone,
    )


def geodetic(
    fresh: list[Direction], origin: Origin, positions: list[tuple[float, float] | None]
) -> list[Direction]:
    """The directions with lat/lon and true bearing; one that fails, or lands off the globe, goes in metres only."""
    try:
        converted = with_geodetic_many(fresh, origin, positions)
    except Exception:
        converted = list(fresh)
        for i, (d, p) in enumerate(zip(fresh, positions)):
            with contextlib.suppress(Exception):  # this one goes in metres only
                (converted[i],) = with_geodetic_many([d], origin, [p])
    # a point thousands of km off the origin has no meaningful lat/lon: that one goes in metres only
    return [g if _geo_ok(g) else d for d, g in zip(fresh, converted)]


def _geo_ok(d: Direction) -> bool:
    """Whether the lat/lon a direction was given are within the wire's bounds."""
    b = d.true_bearing_deg
    return (b is None or -360.0 <= b <= 360.0) and all(
        -90.0 <= g.lat <= 90.0 and -180.0 <= g.lon <= 180.0 for g in d.lookahead_geo
    )


def replan(
    planner: str,
    changes: list[ThreatChange],
    directions: list[Direction],
    zones: Sequence[tuple[str, str]] = (),
    owed: Sequence[str] = (),
) -> ReplanEvent:
    """The event of a batch that changed the threats or zones: what changed, and the units guided afresh.

    ``zones`` are ``(zone id, change)``; they are named in the reason (``zone Z put``)
    before the threats, since ``changes`` lists threats only.  ``owed``: a wave's units
    to be told in the next applies (``world.wave``), named with those told in this one.
    """
    told = {d.unit for d in directions if d.status is not DirectionStatus.NO_GOAL}
    guided = sorted(told.union(owed))
    shown = changes[:MAX_EVENT_ITEMS]
    said = [f"zone {z} {c}" for z, c in zones] + [f"threat {c.threat} {c.change}" for c in shown]
    reason = "; ".join(said[:4])
    if len(zones) + len(changes) > 4:
        reason += f"; and {len(zones) + len(changes) - 4} more"
    return ReplanEvent(
        planner=planner,
        units=guided[:MAX_EVENT_ITEMS],
        reason=reason,
        changes=shown,
        more=len(changes) - len(shown),
        more_units=max(len(guided) - MAX_EVENT_ITEMS, 0),
    )


def rejected(key: str, err: InputError, planner: str, held: int) -> RejectedEvent:
    """The ``rejected`` event of an input on ``key``, with the count of those held back before it."""
    event = RejectedEvent.of(key, err, planner=planner)
    return msgspec.structs.replace(event, suppressed=held) if held else event
