"""Whole-path previews: a unit's detached view, or a what-if on top of it, through ``plan()``.

Sans-I/O: given a ``UnitView`` (``World.view``), an optional decoded request
and a clock, return a ``PlanResult`` or raise ``InputError``.  It never
touches the live world, so a what-if leaves the live stream untouched.

A plain preview drives the unit's own stepper copy from its reported
position, mid-escape included: its first step is the direction the unit was
last given there, the rest are what the stepper will say next.  So it is
exactly what the live stream will do for a unit that moves ``step`` along
each direction.  A what-if with extra
threats drives the same copy after ``world_changed()``, as the live unit
would if they appeared; a new start, goal or parameter starts afresh with the
unit's own seed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import msgspec

from pfp_service.core import PlanResult, Scheduled, Stepper, plan, resolve
from pfp_service.errors import InputError
from pfp_service.service.world import UnitView, unit_key
from pfp_service.wire import MAX_PAYLOAD_BYTES, Goal, PreviewRequest, encode

__all__ = ["fit_reply", "preview"]


def fit_reply(result: PlanResult, limit: int = MAX_PAYLOAD_BYTES) -> bytes:
    """The reply bytes, within ``limit``: the path is thinned (ends kept) and marked if it must be."""
    data = encode(result)
    path = result.path
    keep = len(path)
    while len(data) > limit and keep > 2:
        keep = max(2, int(keep * 0.9 * limit / len(data)))
        stride = (len(path) - 1) / (keep - 1)
        thinned = [path[round(i * stride)] for i in range(keep - 1)] + [path[-1]]
        data = encode(msgspec.structs.replace(result, path=thinned, path_decimated=True))
    return data


def preview(
    view: UnitView,
    request: PreviewRequest | None,
    clock: Callable[[], float],
    budget_s: float,
    max_iter_cap: int,
) -> PlanResult:
    """Preview the path of ``view.unit`` (or a what-if), exactly as the live stepper would drive it.

    With no request: from the unit's current position to its goal, on its own
    stepper, under the threats in force.  A request may replace the start and
    goal, add what-if threats and override delta, step, tolerance, max_iter.

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
    extra = [t.to_threat(t.id) for t in req.threats]
    replaced = {e.id for e in extra}  # a what-if threat with a live id stands in for it
    threats = [t for t in view.threats if t.id not in replaced] + extra
    schedule = [Scheduled(t) for t in threats]
    overrides = (req.start, req.goal, req.delta, req.step, req.tolerance, req.max_iter)
    live = view.stepper
    if live is not None and all(v is None for v in overrides):
        # the live unit's own stepper, mid-escape included: the preview is its stream
        if extra:
            live.world_changed()
        if live.params.max_iter > max_iter_cap:
            live.params = dataclasses.replace(live.params, max_iter=max_iter_cap)
        first = view.last_vector if req.start is None and not extra else None
        return plan(start, goal, schedule, clock=clock, budget_s=budget_s, stepper=live, first_move=first)
    # the live stepper measures the goal term from where the goal was set; a new start or goal starts afresh
    origin = view.origin if view.origin is not None and req.start is None and req.goal is None else start
    params = view.params_for(goal_msg).merged(
        delta=req.delta, step=req.step, tolerance=req.tolerance, max_iter=req.max_iter
    )
    resolved = resolve(params, origin, goal, threats)
    if resolved.max_iter > max_iter_cap:
        resolved = dataclasses.replace(resolved, max_iter=max_iter_cap)
    fresh = Stepper(origin, goal, resolved, view.settings.bounds, unit_key(view.unit))
    return plan(start, goal, schedule, clock=clock, budget_s=budget_s, stepper=fresh)
