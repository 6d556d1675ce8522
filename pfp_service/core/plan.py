"""The simulating driver: move a simulated unit along the stepper's directions.

``walk()`` is the one loop that moves a simulated unit; ``walk_many()`` is
the same for many units under one field, vectorised.  ``plan()`` is the
whole-path answer (``pfp plan``, the preview queryable) built on ``walk``.
It uses the very ``Stepper`` the live daemon uses -- given one, the live
unit's own detached copy, mid-escape included -- so a preview is what the
live stream will do for a unit that moves exactly ``step`` along each
direction (less on the final approach, which ends on the goal): to
``Advice.to``, where ``steprule.judge`` says the step ends.  The live
direction's look-ahead points are ``predict_many``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from enum import StrEnum

import msgspec
import numpy as np

from pfp_service.core import steprule
from pfp_service.core.batch import advise_many
from pfp_service.core.cull import MIN_THREATS, CullIndex
from pfp_service.core.cull import predict as cull_predict
from pfp_service.core.metrics import Epoch, measure
from pfp_service.core.params import PlannerParams, Resolved, resolve
from pfp_service.core.stepper import Advice, Bounds, Stepper, StepStatus
from pfp_service.core.threat import Threat, ThreatField
from pfp_service.core.visibility import Sight
from pfp_service.core.zones import ZoneSet

__all__ = ["PlanResult", "PlanStatus", "Scheduled", "plan", "predict_many", "walk", "walk_many"]


class PlanStatus(StrEnum):
    REACHED = "reached"
    MAX_ITER = "max_iter"
    TRAPPED = "trapped"
    OUT_OF_BOUNDS = "out_of_bounds"
    INVALID = "invalid"


_FROM_STEP = {
    StepStatus.ARRIVED: PlanStatus.REACHED,
    StepStatus.TRAPPED: PlanStatus.TRAPPED,
    StepStatus.OUT_OF_BOUNDS: PlanStatus.OUT_OF_BOUNDS,
    StepStatus.INVALID: PlanStatus.INVALID,
}


class Scheduled(msgspec.Struct, frozen=True):
    """A threat and the step at which it appears (0: from the start)."""

    threat: Threat
    appear_step: int = 0


class UsedParams(msgspec.Struct, frozen=True):
    """The parameters a plan used.  The optimal planner has no delta, max_iter or
    tolerance: those are null for it, and ``step`` is its grid cell in metres."""

    delta: float | None
    step: float
    max_iter: int | None
    tolerance: float | None
    intensity: str
    escape: str


class ThreatView(msgspec.Struct, frozen=True):
    """How much of a path one threat sees: metres of it, and seconds at the unit's speed over the ground."""

    id: str
    metres: float
    seconds: float


class PlanResult(msgspec.Struct, frozen=True, omit_defaults=False):
    """The outcome of one plan; ``pfp plan --json`` prints exactly this.

    ``min_clearance`` is ``None`` when no threat was ever in force.
    ``status`` is ``reached`` only if the final point is within tolerance.
    ``escapes`` names the strategy of each escape made, in order; ``traps``
    counts trapped verdicts (escaped, final, or foreseen and gone round);
    ``escape_steps`` counts steps taken while escaping.  ``planner`` is
    ``pfp`` or ``optimal``; ``lambda`` is the optimal planner's exposure
    weight (``None`` for ``pfp``).  ``path_decimated`` is true when ``path``
    was thinned to fit a reply (``steps`` still counts every step).
    ``min_zone_clearance`` is the path's least distance to a keep-out zone
    (negative: it enters one), ``None`` when no zone was in force.
    """

    status: PlanStatus
    reason: str
    steps: int
    length: float
    exposure: float
    peak_threat: float
    min_clearance: float | None
    final_distance: float
    path: list[tuple[float, float]]
    compute_ms: float
    params: UsedParams
    events: list[str] = []
    escapes: list[str] = []
    traps: int = 0
    escape_steps: int = 0
    planner: str = "pfp"
    lam: float | None = msgspec.field(default=None, name="lambda")
    path_decimated: bool = False
    min_zone_clearance: float | None = None
    # over terrain (``terrain.profile``), absent without it; ``exposure`` is then masked by line of sight
    path_elevation_m: list[float] | None = None
    climb_m: float | None = None
    max_slope_deg: float | None = None
    eta_s: float | None = None
    in_view: list[ThreatView] | None = None
    exposure_unmasked: float | None = None


def _field_at(
    schedule: Sequence[Scheduled],
    step: int,
    intensity: str,
    cache: dict[int, ThreatField],
    zones: ZoneSet | None = None,
    sight: Sight | None = None,
) -> ThreatField:
    active = tuple(s.threat for s in schedule if s.appear_step <= step)
    key = len(active)
    if key not in cache:
        cache[key] = ThreatField(active, intensity, zones, sight)  # type: ignore[arg-type]
    return cache[key]


def walk(
    stepper: Stepper,
    field: ThreatField,
    track: list[tuple[float, float]],
    steps: int,
    deadline: Callable[[], bool] | None = None,
) -> tuple[Advice | None, int]:
    """Advise and move ``steps`` times from ``track[-1]``, appending each new position.

    Returns:
        ``(advice, moved)``: the terminal advice that stopped the walk (``None``
        when all ``steps`` were taken, or the deadline passed) and the moves made.
        ``deadline()`` is asked every 64 moves; true stops the walk.
    """
    x, y = track[-1]
    if stepper.pending is not None:  # a deferring copy: what the unit does once it lands
        stepper.deliberate(field)
    stepper.defer = False
    for k in range(steps):
        adv = stepper.advise(field, x, y)
        if adv.status.terminal:
            return adv, k
        x, y = adv.to
        track.append((x, y))
        if deadline is not None and (k + 1) % 64 == 0 and deadline():
            return None, k + 1
    return None, steps


def walk_many(
    ghosts: list[Stepper], field: ThreatField, starts: np.ndarray, steps: int, cull: CullIndex | None = None
) -> list[list[tuple[float, float]]]:
    """``walk`` for many ghosts under one field: ``steps`` vectorised advisories each.

    Args:
        ghosts: predicting steppers (``Stepper.ghost()``), one per unit; they are moved.
        starts: ``(N, 2)`` first positions.

    Returns:
        Each ghost's track, its start first, ending early at a terminal advice.
    """
    pts = np.array(starts, dtype=np.float64).reshape(-1, 2)
    tracks = [[(float(x), float(y))] for x, y in pts.tolist()]
    live = list(range(len(ghosts)))
    for _ in range(steps):
        if not live:
            break
        advs = advise_many([ghosts[i] for i in live], field, pts[live], cull)
        keep = []
        for i, adv in zip(live, advs):
            if adv.status.terminal:
                continue
            tracks[i].append(adv.to)
            pts[i] = adv.to
            keep.append(i)
        live = keep
    return tracks


def predict_many(
    steppers: list[Stepper],
    field: ThreatField,
    starts: np.ndarray,
    steps: int,
    cull: CullIndex | None = None,
) -> list[list[tuple[float, float]]]:
    """The direction look-ahead: each unit's next ``steps + 1`` positions from ``starts``, as its stepper moves.

    A unit following an escape route looks ahead along it in one compiled
    loop (``Stepper.route_ahead``), or walks a ghost of its stepper
    (``walk_many``) where the route may end within the steps.  Every unit in
    plain descent is stepped in one compiled call (``cull.predict``): the
    same rule as ``Stepper.advise`` (``steprule.judge``), without its trap
    watch (a prediction this short never fills the trap window; a trap is
    judged when the unit gets there).

    Returns:
        One track per unit, its start first, ending early at the goal or the bounds.
    """
    pts0 = np.array(starts, dtype=np.float64).reshape(-1, 2)
    tracks: list[list[tuple[float, float]]] = [[] for _ in steppers]
    esc = []
    for i, s in enumerate(steppers):
        if s.escaping or s.check_terminal():
            track = s.route_ahead(float(pts0[i, 0]), float(pts0[i, 1]), steps)  # compiled, when it can
            if track is None:
                esc.append(i)  # a ghost walks it
            else:
                tracks[i] = track
    if esc:
        for i, t in zip(esc, walk_many([steppers[i].ghost() for i in esc], field, pts0[esc], steps, cull)):
            tracks[i] = t
    plain = np.array(
        [i for i, s in enumerate(steppers) if not (s.escaping or s.check_terminal())], dtype=np.int64
    )
    if plain.size == 0:
        return tracks
    idx = plain.tolist()
    units = np.stack([steppers[i].rules() for i in idx])
    units[:, steprule.WINDOW] = 0.0  # unwatched
    index = cull if cull is not None and len(field) >= MIN_THREATS else None
    trail, lengths = cull_predict(field.packed, index, pts0[plain], units, steps, field.zones)
    rows = trail.tolist()
    for r, (i, n) in enumerate(zip(idx, lengths.tolist())):
        tracks[i] = list(map(tuple, rows[r][:n]))
    return tracks


def plan(
    start: tuple[float, float],
    goal: tuple[float, float],
    schedule: Sequence[Scheduled] = (),
    params: PlannerParams | Resolved | None = None,
    bounds: Bounds | None = None,
    clock: Callable[[], float] | None = None,
    origin: tuple[float, float] | None = None,
    budget_s: float | None = None,
    stepper: Stepper | None = None,
    first_move: tuple[float, float] | None = None,
    field: ThreatField | None = None,
    zones: ZoneSet | None = None,
    sight: Sight | None = None,
) -> PlanResult:
    """Plan a path from ``start`` to ``goal`` among scheduled threats.

    Args:
        start, goal: positions in metres.
        schedule: threats with the step at which each appears.
        params: user parameters (resolved here), already resolved ones, or ``None`` for the defaults.
        bounds: optional mission bounds; leaving them ends the plan.
        clock: a monotonic clock in seconds, for ``compute_ms`` (0 without one).
        origin: where the goal was assigned (``x0`` of the goal term); default ``start``.
            The live daemon's previews pass the unit's origin so they match its stream.
        budget_s: stop with ``max_iter`` once this much ``clock`` time is spent
            (checked every 64 steps; needs ``clock``); measuring the path may
            take as long again (checked every ``MEASURE_CHUNK`` segments).
        stepper: drive this stepper (a live unit's detached copy) instead of a
            fresh one; its goal, origin, parameters and state are used, and
            ``params``, ``bounds`` and ``origin`` are ignored.
        first_move: the unit vector the stepper already gave at ``start``
            (a live unit's last direction): the first step takes it without
            advising again, as the live unit does (``Stepper.step_along``).
        field: the field of every threat in ``schedule`` (all from step 0),
            already built and shared (a preview service's, per world); ignored
            when it does not match them or the intensity.
        zones: the keep-out zones in force throughout (default: ``field``'s,
            if given); no step enters one (``steprule.judge_zoned``).
        sight: threats masked by line of sight over terrain (``core.visibility``;
            default: ``field``'s, if given); the plan's exposure is then the masked one.

    Returns:
        A ``PlanResult``; failure is a status, never an exception.

    Raises:
        DeadlinePassed: twice ``budget_s`` was spent before the path was measured.
    """
    t0 = clock() if clock else 0.0
    schedule = sorted(schedule, key=lambda s: s.appear_step)
    if stepper is not None:
        params = stepper.params
        goal = stepper.goal
    if params is None:
        params = PlannerParams()
    if isinstance(params, PlannerParams):
        params = resolve(params, start, goal, [s.threat for s in schedule])
    cache: dict[int, ThreatField] = {}
    if zones is None and field is not None:
        zones = field.zones
    if sight is None and field is not None:
        sight = field.sight
    if (
        field is not None
        and field.intensity == params.intensity
        and len(field) == len(schedule)
        and field.sight is sight
    ):
        if zones is not None and field.zones is not zones:
            field = field.with_zones(zones)
        cache[len(schedule)] = field  # _field_at's key: the threats active
    appear_steps = sorted({s.appear_step for s in schedule if s.appear_step > 0})
    field = _field_at(schedule, 0, params.intensity, cache, zones, sight)
    epochs: list[Epoch] = []
    epoch_start = 0
    events: list[str] = []
    if stepper is None:
        stepper = Stepper(origin if origin is not None else start, goal, params, bounds)
    track = [(float(start[0]), float(start[1]))]
    k = 0
    if first_move is not None and params.max_iter > 0:
        to = stepper.step_along(*track[0], *first_move)
        if to is not None:  # else the first advice says why it stands
            track.append(to)
            k = 1
    status = PlanStatus.MAX_ITER
    reason = f"max_iter ({params.max_iter}) reached"
    spent = None
    if budget_s is not None and clock is not None:
        t_end = t0 + budget_s

        def spent() -> bool:
            return clock() > t_end

    while True:
        seg_end = min(appear_steps[0] if appear_steps else params.max_iter, params.max_iter)
        adv, moved = walk(stepper, field, track, seg_end - k, spent)
        k += moved
        if adv is not None:
            status, reason = _FROM_STEP[adv.status], adv.reason
            break
        if k < seg_end:  # the deadline passed
            reason = f"time budget of {(budget_s or 0.0) * 1e3:g} ms spent after {k} steps"
            break
        if appear_steps and k == appear_steps[0]:
            appear_steps.pop(0)
            x, y = track[-1]
            epochs.append(Epoch(epoch_start, k, field))
            epoch_start = k
            field = _field_at(schedule, k, params.intensity, cache, zones, sight)
            new = [s.threat.id for s in schedule if s.appear_step == k]
            events.append(f"step {k}: threat {', '.join(new)} appeared; unit at ({x:.6g}, {y:.6g})")
            stepper.world_changed()
            continue
        # max_iter moves made: one last advice says whether the unit stands at the goal
        last = stepper.advise(field, *track[-1])
        if last.status.terminal:
            status, reason = _FROM_STEP[last.status], last.reason
        break
    x, y = track[-1]
    epochs.append(Epoch(epoch_start, k, field))
    for name in stepper.escapes:  # a start inside a core or a zone is left first: say so
        if name.startswith("leave core "):
            events.insert(
                0,
                f"start inside the core of threat {name[len('leave core ') :]}: left it by the shortest way out",
            )
        elif name.startswith("leave zone "):
            events.insert(
                0, f"start inside zone {name[len('leave zone ') :]}: left it by the shortest way out"
            )
    path = np.array(track)
    measured_by = None
    if budget_s is not None and clock is not None:
        t_measured = t0 + 2.0 * budget_s

        def measured_by() -> bool:
            return clock() > t_measured

    m = measure(path, epochs, measured_by)
    final = math.hypot(goal[0] - x, goal[1] - y)
    if status is PlanStatus.REACHED and not final <= params.tolerance:  # belt and braces
        status, reason = PlanStatus.INVALID, "internal: reached outside tolerance"
    return PlanResult(
        status=status,
        reason=reason,
        steps=k,
        length=m.length,
        exposure=m.exposure,
        peak_threat=m.peak_threat,
        min_clearance=m.min_clearance if math.isfinite(m.min_clearance) else None,
        final_distance=final,
        path=track,
        compute_ms=((clock() - t0) * 1e3) if clock else 0.0,
        params=UsedParams(
            params.delta, params.step, params.max_iter, params.tolerance, params.intensity, params.escape
        ),
        events=events,
        escapes=stepper.escapes,
        traps=stepper.traps,
        escape_steps=stepper.escape_steps,
        min_zone_clearance=m.min_zone_clearance if math.isfinite(m.min_zone_clearance) else None,
    )
