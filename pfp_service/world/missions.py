"""A unit's mission: fixed once per goal (its ``x0`` and resolved parameters), kept across restarts and takeovers.

A mission restored or shared for this very goal is kept, so a restart or a
takeover guides the unit exactly as before; otherwise ``x0`` is where the
unit is now.  A goal closer than ``LENGTH_MIN_M`` is planned with a step of
that length, so it has arrived; a mission the planner cannot plan
(``constraints.reach_problem``) is refused as a value.  Pure values in and out.
"""

from __future__ import annotations

import math

from pfp_service.constraints import LENGTH_MIN_M, reach_problem
from pfp_service.core import Resolved, Stepper, ThreatField, resolve
from pfp_service.core.params import FieldStats
from pfp_service.errors import InputError
from pfp_service.wire import Goal
from pfp_service.world import mobility
from pfp_service.world.events import MissionRecord, WorldSettings
from pfp_service.world.units import Started, UnitRecord

__all__ = ["Shared", "fix", "start"]

Shared = tuple[Goal, tuple[float, float], Resolved]  # a mission fixed: its goal, x0 and parameters


def fix(
    goal: Goal,
    position: tuple[float, float] | None,
    shared: Shared | None,
    settings: WorldSettings,
    fld: ThreatField,
    stats: FieldStats | None,
) -> Shared | InputError:
    """The mission for ``goal`` of a unit at ``position`` (which a kept ``shared`` mission does without).

    Returns:
        The mission, or why it is refused (the goal's field path and the reason).
    """
    refused = mobility.refusal(goal)  # a goal put in-process skipped the decoder's check
    if refused is not None:
        return refused
    to = (goal.position[0], goal.position[1])
    if shared is not None and shared[0] == goal:
        origin, resolved = shared[1], shared[2]
    else:
        assert position is not None
        origin = position
        params = settings.params_for(goal)
        if math.dist(origin, to) < LENGTH_MIN_M and (params.step or 0.0) < LENGTH_MIN_M:
            params = params.merged(step=LENGTH_MIN_M)  # closer than the planner resolves: arrived
        resolved = resolve(params, origin, to, fld.threats, stats)
    problem = reach_problem(math.dist(origin, to), resolved.step, resolved.max_iter, resolved.tolerance)
    if problem is not None:
        return InputError("$.step" if goal.step is not None else "$.position", problem)
    return (goal, origin, resolved)


def start(
    rec: UnitRecord, settings: WorldSettings, fld: ThreatField, stats: FieldStats | None
) -> tuple[Started, MissionRecord] | InputError:
    """The mission of ``rec``'s goal and the stepper that guides the unit on it (the record is not touched).

    Returns:
        What the unit's owner keeps (``Units.started``) and what durable
        state must keep of the mission, or why it is refused.
    """
    assert rec.goal is not None
    mission = fix(rec.goal, rec.position, rec.shared, settings, fld, stats)
    if isinstance(mission, InputError):
        return mission
    goal, origin, resolved = mission
    stepper = Stepper(origin, (goal.position[0], goal.position[1]), resolved, settings.bounds, rec.key)
    stepper.defer = settings.deliberation == "deferred"
    stepper.track()  # a live unit: guided whatever it does between two reports (core.tracking)
    stepper.pace(rec.progress.speed_mps)
    return Started(mission, stepper), MissionRecord(rec.id, rec.epoch, origin, goal, resolved)
