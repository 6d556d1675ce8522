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

from pfp_service.core import StepStatus, Threat, ThreatField
from pfp_service.core.advice import Advice
from pfp_service.core.batch import advise_many
from pfp_service.core.cull import RELATIVE_BOUND, CullIndex, corridors_meet, influence_boxes
from pfp_service.core.tracking import PURSUIT_TOLERANCE_STEPS, Route
from pfp_service.core.visibility import Sight
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
    "reached",
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
# over terrain, a corridor is looked at every this many metres (at most this many points) for a threat's sight
SEEN_STEP_M = 25.0
SEEN_SAMPLES = 513
ZONE_REACH = 0.25  # a zone's box is widened by this share of its diagonal: its barrier's reach, generously
# an escaping or deliberating unit may leave its straight corridor (an escape's detour, a foresight's
# path): its corridor is then the box of its position and goal, widened by this share of their distance
WIDE_REACH = 0.5
WIDE_SAMPLES = 24  # over terrain, that box is looked at on this many points a side for a threat's sight
WIDE_BLOCK = 256  # ... this many units' points at once (4.7 MB of points and levels)
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
        unit=rec.id, seq=rec.seq, status=DirectionStatus.NO_GOAL, vector=(0.0, 0.0), planner=planner
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


def reached(
    guided: list[UnitRecord],
    touched: list[Threat],
    intensity: str,
    zones: Sequence[tuple[float, float, float, float]] = (),
    sight: Sight | None = None,
    wide: Sequence[bool] | None = None,
) -> list[bool]:
    """Which units (each with a stepper and a position) a change of the ``touched`` threats or zones can reach.

    A unit is reached when a touched threat's influence box (where it is not
    culled, ``cull.influence_boxes``), or a touched zone's box (``zones``:
    ``(xmin, ymin, xmax, ymax)``, widened by ``ZONE_REACH`` of its diagonal for
    the barrier that bends descent away near its edge), meets the unit's
    corridor to its goal (``cull.corridors_meet``).  Over terrain (``sight``) a
    threat reaches only a unit it can see somewhere along that corridor
    (``_seen``): behind a ridge its term is zero, and so is its pull on the
    unit's direction.  Every other unit's direction is unchanged within the
    cull bound.  A unit marked ``wide`` (escaping or deliberating: it may
    leave its corridor) is reached when a touched threat or zone meets the
    box of its position and goal widened by ``WIDE_REACH`` of their
    distance, and over terrain when the threat sees somewhere in that box
    (``_seen_in_boxes``).  If the vectorised test fails, every unit counts as
    reached: dearer, never wrong.
    """
    if not guided:
        return []
    try:
        n = len(guided)  # each unit's start and goal in one pass: a wave's first look at every unit
        ends = itertools.chain.from_iterable((*r.position, *r.stepper.goal) for r in guided)  # type: ignore[misc, union-attr]
        flat = np.fromiter(ends, dtype=float, count=4 * n).reshape(n, 4)
        starts, goals = flat[:, :2], flat[:, 2:]
        hit = np.zeros(n, dtype=bool)
        if touched:
            boxes = influence_boxes(ThreatField(touched, intensity).packed)  # type: ignore[arg-type]
            if sight is None:
                hit |= corridors_meet(starts, goals, boxes)
            else:
                for threat, box in zip(touched, boxes, strict=True):
                    near = corridors_meet(starts, goals, box[None, :])
                    if near.any():
                        near[near] = _seen(threat, box, starts[near], goals[near], intensity, sight)
                        hit |= near
        if len(zones):
            zb = np.array(zones, dtype=float).reshape(-1, 4)
            pad = ZONE_REACH * np.hypot(zb[:, 2] - zb[:, 0], zb[:, 3] - zb[:, 1])[:, None]
            hit |= corridors_meet(starts, goals, zb + np.hstack([-pad, -pad, pad, pad]))
        if wide is not None and any(wide):
            w = np.flatnonzero(np.asarray(wide, dtype=bool) & ~hit)
            hit[w] = _wide(starts[w], goals[w], touched, intensity, zones, sight)
        return hit.tolist()
    except Exception:
        return [True] * len(guided)


def _wide(
    starts: np.ndarray,
    goals: np.ndarray,
    touched: list[Threat],
    intensity: str,
    zones: Sequence[tuple[float, float, float, float]],
    sight: Sight | None,
) -> np.ndarray:
    """``reached`` for units that may leave their corridor: their boxes widened by ``WIDE_REACH``."""
    pad = WIDE_REACH * np.hypot(*(goals - starts).T)[:, None]
    lo, hi = np.minimum(starts, goals) - pad, np.maximum(starts, goals) + pad
    units = np.hstack([lo, hi])  # (n, 4): x0, y0, x1, y1
    hit = np.zeros(len(units), dtype=bool)
    if len(zones):
        zb = np.array(zones, dtype=float).reshape(-1, 4)
        zpad = ZONE_REACH * np.hypot(zb[:, 2] - zb[:, 0], zb[:, 3] - zb[:, 1])[:, None]
        hit |= _boxes_meet(units, zb + np.hstack([-zpad, -zpad, zpad, zpad])).any(axis=1)
    if touched:
        boxes = influence_boxes(ThreatField(touched, intensity).packed)  # type: ignore[arg-type]
        meet = _boxes_meet(units, boxes)  # (n, threats)
        for j, threat in enumerate(touched):
            w = np.flatnonzero(meet[:, j] & ~hit)
            if len(w):
                hit[w] = (
                    True if sight is None else _seen_in_boxes(threat, boxes[j], units[w], intensity, sight)
                )
    return hit


def _boxes_meet(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(len(a), len(b))``: whether box ``a[i]`` meets box ``b[j]`` (``x0, y0, x1, y1``)."""
    return (
        (a[:, None, 0] <= b[None, :, 2])
        & (b[None, :, 0] <= a[:, None, 2])
        & (a[:, None, 1] <= b[None, :, 3])
        & (b[None, :, 1] <= a[:, None, 3])
    )


def _seen_in_boxes(
    threat: Threat, box: np.ndarray, units: np.ndarray, intensity: str, sight: Sight
) -> np.ndarray:
    """Whether ``threat`` sees anywhere in the part of each unit's box (``(n, 4)``) within its own ``box``.

    Each part is looked at on ``WIDE_SAMPLES`` points a side, all units' at
    once under one field blind and one masked (``_seen``'s bound): a wave
    re-judges hundreds of deliberating units, and a field a unit cost a
    millisecond each.
    """
    blind_f = ThreatField([threat], intensity)  # type: ignore[arg-type]
    masked_f = ThreatField([threat], intensity, sight=sight)  # type: ignore[arg-type]
    lo = np.maximum(units[:, :2], box[None, :2])  # (n, 2): x0, y0 of each part
    hi = np.minimum(units[:, 2:], box[None, 2:])
    t = np.linspace(0.0, 1.0, WIDE_SAMPLES)
    xs = lo[:, None, 0] + t[None, :] * (hi[:, 0] - lo[:, 0])[:, None]  # (n, k)
    ys = lo[:, None, 1] + t[None, :] * (hi[:, 1] - lo[:, 1])[:, None]
    k, out = WIDE_SAMPLES, np.zeros(len(units), dtype=bool)
    for a in range(0, len(units), WIDE_BLOCK):  # the points' memory bounded, whatever the fleet
        pts = np.empty((len(units[a : a + WIDE_BLOCK]), k, k, 2))
        pts[..., 0] = xs[a : a + WIDE_BLOCK, None, :]
        pts[..., 1] = ys[a : a + WIDE_BLOCK, :, None]
        blind, masked = blind_f.level(pts), masked_f.level(pts)
        out[a : a + WIDE_BLOCK] = ((blind > 0.0) & (masked >= RELATIVE_BOUND * blind)).any(axis=(1, 2))
    return out


def _seen(
    threat: Threat, box: np.ndarray, starts: np.ndarray, goals: np.ndarray, intensity: str, sight: Sight
) -> np.ndarray:
    """Whether ``threat`` sees each corridor (start to goal) anywhere inside its influence box.

    The corridor is sampled every ``SEEN_STEP_M`` (at most ``SEEN_SAMPLES`` points); a
    sample is seen where the masked level is at least ``RELATIVE_BOUND`` of the
    blind one (the cull's own bound on what a term may change).
    """
    length = float(np.hypot(*(goals - starts).T).max(initial=0.0))
    k = int(min(SEEN_SAMPLES, max(2, math.ceil(length / SEEN_STEP_M) + 1)))
    t = np.linspace(0.0, 1.0, k)[None, :, None]
    pts = starts[:, None, :] + t * (goals - starts)[:, None, :]  # (units, k, 2)
    inside = (
        (pts[..., 0] >= box[0]) & (pts[..., 0] <= box[2]) & (pts[..., 1] >= box[1]) & (pts[..., 1] <= box[3])
    )
    blind = ThreatField([threat], intensity).level(pts)  # type: ignore[arg-type]
    masked = ThreatField([threat], intensity, sight=sight).level(pts)  # type: ignore[arg-type]
    return np.asarray((inside & (blind > 0.0) & (masked >= RELATIVE_BOUND * blind)).any(axis=1))


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
