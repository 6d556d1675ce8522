"""The preview driver: move a simulated unit along the stepper's directions.

``plan()`` is the whole-path answer (``pfp plan``, the preview queryable).  It
uses the very ``Stepper`` the live daemon uses, so a preview is what the live
stream will do for a unit that moves exactly ``step`` along each direction.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from enum import StrEnum

import msgspec
import numpy as np

from pfp_service.core.metrics import Epoch, measure
from pfp_service.core.params import PlannerParams, Resolved, resolve
from pfp_service.core.stepper import Bounds, Stepper, StepStatus
from pfp_service.core.threat import Threat, ThreatField

__all__ = ["PlanResult", "PlanStatus", "Scheduled", "plan"]


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
    delta: float
    step: float
    max_iter: int
    tolerance: float
    intensity: str
    escape: str


class PlanResult(msgspec.Struct, frozen=True, omit_defaults=False):
    """The outcome of one plan; ``pfp plan --json`` prints exactly this.

    ``min_clearance`` is ``None`` when no threat was ever in force.
    ``status`` is ``reached`` only if the final point is within tolerance.
    ``escapes`` names the strategy of each escape made, in order; ``traps``
    counts trapped verdicts (escaped, final, or foreseen and gone round);
    ``escape_steps`` counts steps taken while escaping.  ``planner`` is
    ``pfp`` or ``optimal``; ``lambda`` is the optimal planner's exposure
    weight (``None`` for ``pfp``).
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


def _field_at(
    schedule: Sequence[Scheduled], step: int, intensity: str, cache: dict[int, ThreatField]
) -> ThreatField:
    active = tuple(s.threat for s in schedule if s.appear_step <= step)
    key = len(active)
    if key not in cache:
        cache[key] = ThreatField(active, intensity)  # type: ignore[arg-type]
    return cache[key]


def plan(
    start: tuple[float, float],
    goal: tuple[float, float],
    schedule: Sequence[Scheduled] = (),
    params: PlannerParams | Resolved | None = None,
    bounds: Bounds | None = None,
    clock: Callable[[], float] | None = None,
    origin: tuple[float, float] | None = None,
    budget_s: float | None = None,
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
            (checked every 64 steps; needs ``clock``).

    Returns:
        A ``PlanResult``; failure is a status, never an exception.
    """
    t0 = clock() if clock else 0.0
    schedule = sorted(schedule, key=lambda s: s.appear_step)
    if params is None:
        params = PlannerParams()
    if isinstance(params, PlannerParams):
        params = resolve(params, start, goal, [s.threat for s in schedule])
    cache: dict[int, ThreatField] = {}
    appear_steps = sorted({s.appear_step for s in schedule if s.appear_step > 0})
    field = _field_at(schedule, 0, params.intensity, cache)
    epochs: list[Epoch] = []
    epoch_start = 0
    events: list[str] = []
    stepper = Stepper(origin if origin is not None else start, goal, params, bounds)
    x, y = float(start[0]), float(start[1])
    track = [(x, y)]
    step = params.step
    status = PlanStatus.MAX_ITER
    reason = f"max_iter ({params.max_iter}) reached"
    next_pop = appear_steps.pop(0) if appear_steps else -1
    k = 0
    while True:
        if k == next_pop:
            epochs.append(Epoch(epoch_start, k, field))
            epoch_start = k
            field = _field_at(schedule, k, params.intensity, cache)
            new = [s.threat.id for s in schedule if s.appear_step == k]
            events.append(f"step {k}: threat {', '.join(new)} appeared at ({x:.6g}, {y:.6g})")
            stepper.world_changed()
            next_pop = appear_steps.pop(0) if appear_steps else -1
        adv = stepper.advise(field, x, y)
        if adv.status.terminal:
            status, reason = _FROM_STEP[adv.status], adv.reason
            break
        if k >= params.max_iter:
            break
        x += step * adv.dx
        y += step * adv.dy
        track.append((x, y))
        k += 1
        if budget_s is not None and clock is not None and k % 64 == 0 and clock() - t0 > budget_s:
            reason = f"time budget of {budget_s * 1e3:g} ms spent after {k} steps"
            break
    epochs.append(Epoch(epoch_start, k, field))
    path = np.array(track)
    m = measure(path, epochs)
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
    )
