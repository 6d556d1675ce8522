"""Whole-path previews: the live world, or a what-if on top of it, through ``plan()``.

Sans-I/O: given the world, a unit id, an optional decoded request and a clock,
return a ``PlanResult`` or raise ``InputError``.  It reads the world and never
changes it, so a what-if leaves the live stream untouched.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from pfp_service.core import PlanResult, Scheduled, plan, resolve
from pfp_service.errors import InputError
from pfp_service.service.world import World
from pfp_service.wire import Goal, PreviewRequest

__all__ = ["preview"]


def preview(
    world: World,
    unit_id: str,
    request: PreviewRequest | None,
    clock: Callable[[], float],
    budget_s: float,
    max_iter_cap: int,
) -> PlanResult:
    """Preview the path of ``unit_id`` (or a what-if), exactly as the live stepper would drive it.

    With no request: from the unit's current position to its goal, from its
    goal's origin, under the threats in force.  A request may replace the start
    and goal, add what-if threats and override delta, step, tolerance, max_iter.

    Raises:
        InputError: the unit is unknown or has no goal and the request gives none.
    """
    rec = world.units.get(unit_id)
    req = request or PreviewRequest()
    start = req.start if req.start is not None else (rec.position if rec is not None else None)
    if start is None:
        raise InputError("$.start", f"unit {unit_id!r} has reported no position; give a start")
    goal_msg = rec.goal if rec is not None else None
    if req.goal is not None:
        goal_msg = Goal(position=req.goal)
    if goal_msg is None:
        raise InputError("$.goal", f"unit {unit_id!r} has no goal; give a goal")
    goal = (goal_msg.position[0], goal_msg.position[1])
    start = (start[0], start[1])
    # the live stepper measures the goal term from where the goal was set; a new start or goal starts afresh
    origin = start
    if rec is not None and rec.origin is not None and req.start is None and req.goal is None:
        origin = rec.origin
    threats = world.threat_list()
    extra = [t.to_threat(t.id) for t in req.threats]
    replaced = {e.id for e in extra}  # a what-if threat with a live id stands in for it
    threats = [t for t in threats if t.id not in replaced] + extra
    overrides = (req.start, req.goal, req.delta, req.step, req.tolerance, req.max_iter)
    if rec is not None and rec.stepper is not None and all(v is None for v in overrides):
        # the live unit's own parameters, fixed when its goal was set: the preview is its stream
        resolved = rec.stepper.params
    else:
        params = world.params_for(goal_msg).merged(
            delta=req.delta, step=req.step, tolerance=req.tolerance, max_iter=req.max_iter
        )
        resolved = resolve(params, origin, goal, threats)
    if resolved.max_iter > max_iter_cap:
        resolved = dataclasses.replace(resolved, max_iter=max_iter_cap)
    return plan(
        start,
        goal,
        [Scheduled(t) for t in threats],
        resolved,
        bounds=world.settings.bounds,
        clock=clock,
        origin=origin,
        budget_s=budget_s,
    )
