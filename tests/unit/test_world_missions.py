"""A unit's mission (world/missions.py): fixed where the unit is, kept when shared for the same goal, refused as a value."""

from __future__ import annotations

import pytest

from pfp_service.core import PlannerParams, ThreatField, resolve
from pfp_service.errors import InputError
from pfp_service.wire import Goal, UnitPhase
from pfp_service.world import missions
from pfp_service.world.events import MissionRecord, WorldSettings
from pfp_service.world.units import Units

pytestmark = pytest.mark.unit

S = WorldSettings(planner=PlannerParams(intensity="density", delta=0.08))
EMPTY = ThreatField([], "density")


def test_a_mission_is_fixed_where_the_unit_is():
    goal = Goal(position=(100.0, 0.0))
    m = missions.fix(goal, (0.0, 0.0), None, S, EMPTY, None)
    assert not isinstance(m, InputError)
    assert m[0] == goal and m[1] == (0.0, 0.0) and m[2].step > 0


def test_a_mission_shared_for_this_very_goal_is_kept_and_one_for_another_goal_is_not():
    goal = Goal(position=(100.0, 0.0))
    theirs = resolve(S.planner, (-50.0, 0.0), (100.0, 0.0), ())
    kept = missions.fix(goal, (0.0, 0.0), (goal, (-50.0, 0.0), theirs), S, EMPTY, None)
    assert kept == (goal, (-50.0, 0.0), theirs)
    other = missions.fix(goal, (0.0, 0.0), (Goal(position=(9.0, 9.0)), (-50.0, 0.0), theirs), S, EMPTY, None)
    assert not isinstance(other, InputError) and other[1] == (0.0, 0.0)


def test_a_goal_the_planner_cannot_reach_in_max_iter_steps_is_refused_on_its_step():
    goal = Goal(position=(1e6, 0.0), step=0.01)
    err = missions.fix(goal, (0.0, 0.0), None, S, EMPTY, None)
    assert isinstance(err, InputError) and err.path == "$.step"


def test_a_goal_closer_than_the_planner_resolves_is_planned_as_arrived():
    m = missions.fix(Goal(position=(1e-9, 0.0)), (0.0, 0.0), None, S, EMPTY, None)
    assert not isinstance(m, InputError) and m[2].step >= missions.LENGTH_MIN_M


def test_start_gives_the_unit_a_stepper_and_names_what_durable_state_keeps():
    book = Units()
    rec = book.add("u", True, 0.0, reported=True)
    book.reported(rec, (0.0, 0.0), 1, None, 0.0, 0.0)
    book.set_goal(rec, Goal(position=(100.0, 0.0)), None)
    out = missions.start(rec, S, EMPTY, None)
    assert not isinstance(out, InputError)
    started, rec_out = out
    assert rec.stepper is None  # pure: the record is the owner's to write
    assert isinstance(rec_out, MissionRecord) and rec_out.epoch == 1 and rec_out.origin == (0.0, 0.0)
    book.started(rec, started)
    assert rec.stepper is not None and rec.stepper.goal == (100.0, 0.0) and rec.origin == (0.0, 0.0)
    assert rec.shared is not None and rec.shared[0] == rec.goal and rec.phase is UnitPhase.GUIDED
    assert not rec.stepper.defer
    deferred = missions.start(rec, WorldSettings(deliberation="deferred"), EMPTY, None)
    assert not isinstance(deferred, InputError) and deferred[0].stepper.defer
