"""Whole-path previews: a unit's detached view, or a what-if on top of it, through ``plan()``.

Sans-I/O: given a ``UnitView`` (``World.view``), an optional decoded request
and a clock, return a ``PlanResult`` or raise ``InputError``.  It never
touches the live world, so a what-if leaves the live stream untouched.

``admit`` bounds a request's cost before any work is done on it: the steps
its geometry needs at its step, its what-if count, and the escape route a
what-if threat as wide as it asks could make the stepper resample.  Each
refusal is an ``InputError`` naming the field; what passes is given a
``Cost``, which the preview service uses to order the work (light before heavy).

A plain preview drives the unit's own stepper copy from its reported
position, mid-escape included: its first step is the direction the unit was
last given there, the rest are what the stepper will say next.  So it is
exactly what the live stream will do for a unit that moves ``step`` along
each direction.  A what-if with extra
threats drives the same copy after ``world_changed()``, as the live unit
would if they appeared; a new start, goal or parameter starts afresh with the
unit's own seed.

Over terrain the path is measured over the ground (``Ground.over_ground``):
its elevations, climb, steepest ground and ``eta_s`` at the unit's own
mobility, its speed override included, as ``pfp plan --terrain`` measures a
plan's.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import msgspec

from pfp_service.core import PlanResult, Scheduled, Stepper, Threat, ThreatField, plan, resolve
from pfp_service.core.params import FieldStats, field_stats
from pfp_service.errors import InputError
from pfp_service.wire import Goal, PreviewRequest
from pfp_service.wire.messages.structs import DEFAULT_SHAPE
from pfp_service.world import translate
from pfp_service.world.mobility import mobility_of
from pfp_service.world.terrain import sight_of
from pfp_service.world.world import UnitView, unit_key

__all__ = ["HEAVY_STEPS", "MAX_PREVIEW_WHATIFS", "Cost", "admit", "preview"]

MAX_PREVIEW_WHATIFS = 64  # what-if threats one preview may add (the wire takes 256: a planner refuses more)
HEAVY_STEPS = 20_000  # a preview bounded above this many steps (or a route this long) is heavy
ROUTE_SIGMAS = 6.0  # a route search's grid reaches three spreads of the widest threat past each end


class Cost(msgspec.Struct, frozen=True):
    """What an admitted preview may cost at most: its steps and its escape routes' resampled points."""

    steps: float
    route_points: float
    whatifs: int

    @property
    def heavy(self) -> bool:
        return max(self.steps, self.route_points) > HEAVY_STEPS or self.whatifs > MAX_PREVIEW_WHATIFS // 4


def admit(
    view: UnitView, request: PreviewRequest | None, max_iter_cap: int, stats: FieldStats | None = None
) -> Cost:
    """The cost bound of a preview, or why it is out of proportion, before any work is done on it.

    Refused, in this order: a step that needs more than ``max_iter_cap``
    steps to cover the start-goal distance (``$.step``, or ``$.goal`` when the
    step is the goal's); more than ``MAX_PREVIEW_WHATIFS`` what-ifs
    (``$.threats``); a what-if so wide that an escape route round it
    (the route search's grid spans the distance plus three spreads on each
    side, and its route is resampled at the step) would have more than
    ``max_iter_cap`` points (``$.threats[i].sigma_range``, or ``.params`` for
    another shape).  A plain preview (the unit's own mission, accepted by the
    world) is never refused: its walk is capped instead.
    ``stats`` is ``field_stats(view.threats)``, kept by a caller per field.

    Raises:
        InputError: naming the field, with the bound and what would pass.
    """
    req = request or PreviewRequest()
    start = req.start if req.start is not None else view.position
    goal_msg = Goal(position=req.goal) if req.goal is not None else view.goal
    if start is None or goal_msg is None:  # ``preview`` refuses it, at no cost
        if len(req.threats) > MAX_PREVIEW_WHATIFS:
            raise InputError(
                "$.threats", f"{len(req.threats)} what-if threats; at most {MAX_PREVIEW_WHATIFS}"
            )
        return Cost(0.0, 0.0, len(req.threats))
    dist = math.hypot(goal_msg.position[0] - start[0], goal_msg.position[1] - start[1])
    live = view.stepper
    fresh = live is None or any(v is not None for v in (req.start, req.goal, req.step, req.max_iter))
    if fresh:
        given = req.step if req.step is not None else view.params_for(goal_msg).step
        path = "$.step" if req.step is not None else "$.goal"
        if given is None:  # derived (``resolve``): a few thousand steps at most, whatever the distance
            base = stats if stats is not None else field_stats(view.threats)
            narrowest = min((t.min_sigma() for t in whatifs(req)), default=math.inf)
            merged = FieldStats(min(base.min_sigma, narrowest), base.median_ratio)
            given = resolve(view.params_for(goal_msg), start, goal_msg.position, stats=merged).step
            path = ""
        step = given
    else:
        assert live is not None
        step, path = live.params.step, ""
    steps = dist / step
    if path and steps > max_iter_cap:
        raise InputError(
            path,
            f"the goal is {dist:.6g} m from the start: {steps:.3g} steps of {step:.3g} m, more than a "
            f"preview's {max_iter_cap}; use a step of at least {dist / max_iter_cap:.3g} m",
        )
    step_m = step
    if len(req.threats) > MAX_PREVIEW_WHATIFS:
        raise InputError(
            "$.threats", f"{len(req.threats)} what-if threats; a preview takes at most {MAX_PREVIEW_WHATIFS}"
        )
    route_points = 0.0
    if req.threats:
        widths = [t.max_sigma() for t in whatifs(req)]
        widest = max(range(len(widths)), key=widths.__getitem__)
        route_points = (dist + ROUTE_SIGMAS * widths[widest]) / step_m
        if route_points > max_iter_cap:
            field = "sigma_range" if req.threats[widest].shape == DEFAULT_SHAPE else "params"
            raise InputError(
                f"$.threats[{widest}].{field}",
                f"a what-if threat {widths[widest]:.3g} m wide: an escape route round it could "
                f"have {route_points:.3g} points at a {step_m:.3g} m step, more than a preview's {max_iter_cap}",
            )
    return Cost(min(steps, float(max_iter_cap)), route_points, len(req.threats))


def whatifs(req: PreviewRequest) -> list[Threat]:
    """The request's what-if threats as core values, or the first its shape refuses, by index and field.

    Raises:
        InputError: ``$.threats[i].<field>``.
    """
    out = []
    for i, t in enumerate(req.threats):
        try:
            out.append(translate.threat(t, t.id))
        except translate.ShapeError as exc:
            raise translate.refusal(exc, f"$.threats[{i}]") from exc
    return out


def preview(
    view: UnitView,
    request: PreviewRequest | None,
    clock: Callable[[], float],
    budget_s: float,
    max_iter_cap: int,
    field: ThreatField | None = None,
) -> PlanResult:
    """Preview the path of ``view.unit`` (or a what-if), exactly as the live stepper would drive it.

    With no request: from the unit's current position to its goal, on its own
    stepper, under the threats in force.  A request may replace the start and
    goal, add what-if threats and override delta, step, tolerance, max_iter.

    ``field``, when given, is the field of ``view.threats`` (built once per
    world and shared): a preview plans on it, or on it plus its what-ifs
    (``ThreatField.plus``), instead of packing every threat again.

    Raises:
        InputError: the unit is unknown or has no goal and the request gives none.
    """
    req = request or PreviewRequest()
    start = req.start if req.start is not None else view.position
    if start is None:
        raise InputError("$.start", f"unit {view.unit!r} has reported no position; give a start")
    goal_msg = view.goal
    if req.goal is not None:
        goal_msg = Goal(position=req.goal)
    if goal_msg is None:
        raise InputError("$.goal", f"unit {view.unit!r} has no goal; give a goal")
    goal = (goal_msg.position[0], goal_msg.position[1])
    start = (start[0], start[1])
    extra = whatifs(req)
    replaced = {e.id for e in extra}  # a what-if threat with a live id stands in for it
    threats = [t for t in view.threats if t.id not in replaced] + extra
    schedule = [Scheduled(t) for t in threats]
    shared = field
    if field is not None and extra:  # the world's field, its rows reused: only the what-ifs are packed
        shared = field.plus(extra, replaced)
    if shared is None and view.settings.terrain is not None:  # over terrain: each threat masked by its sight
        sight = sight_of(view.settings.terrain, view.height_m)  # the unit seen at its own class's height
        shared = ThreatField(threats, view.settings.planner.intensity, sight=sight)
    if view.zones:  # the keep-out zones in force: the preview respects them as the live unit does
        base = shared if shared is not None else ThreatField(threats, view.settings.planner.intensity)
        shared = base.with_zones(view.zones)
    overrides = (req.start, req.goal, req.delta, req.step, req.tolerance, req.max_iter)
    live = view.stepper
    if live is not None and all(v is None for v in overrides):
        # the live unit's own stepper, mid-escape included: the preview is its stream
        if extra:
            live.world_changed()
        if live.params.max_iter > max_iter_cap:
            live.params = dataclasses.replace(live.params, max_iter=max_iter_cap)
        first = view.last_vector if req.start is None and not extra else None
        walked = plan(
            start,
            goal,
            schedule,
            clock=clock,
            budget_s=budget_s,
            stepper=live,
            first_move=first,
            field=shared,
        )
        return _over_ground(view, goal_msg, walked)
    # the live stepper measures the goal term from where the goal was set; a new start or goal starts afresh
    origin = view.origin if view.origin is not None and req.start is None and req.goal is None else start
    params = view.params_for(goal_msg).merged(
        delta=req.delta, step=req.step, tolerance=req.tolerance, max_iter=req.max_iter
    )
    resolved = resolve(params, origin, goal, threats)
    if resolved.max_iter > max_iter_cap:
        resolved = dataclasses.replace(resolved, max_iter=max_iter_cap)
    fresh = Stepper(origin, goal, resolved, view.settings.bounds, unit_key(view.unit))
    walked = plan(start, goal, schedule, clock=clock, budget_s=budget_s, stepper=fresh, field=shared)
    return _over_ground(view, goal_msg, walked)


def _over_ground(view: UnitView, goal: Goal, result: PlanResult) -> PlanResult:
    """``result`` measured over the terrain, if there is one: its elevations, climb, steepest ground and ETA
    at the unit's own mobility (its goal's over its states', overrides included: ``world.mobility``)."""
    ground = view.settings.terrain
    if ground is None or not result.path:
        return result
    own = mobility_of(goal, view.standing)
    return msgspec.structs.replace(result, **ground.over_ground(result.path, own))
