"""Bulkheads in the world: what one input, one deliberation result or one unit carries stays with it.

Plain numbers in, no Zenoh: payloads go through the wire decoders exactly as
the node feeds them (a refusal becomes ``InputRejected``), so what is tested
is what a hostile unit can send.
"""

from __future__ import annotations

import json
import math

import pytest

from pfp_service.core import PlannerParams, Resolved
from pfp_service.errors import InputError
from pfp_service.wire import (
    ArrivedEvent,
    DirectionStatus,
    ForgottenEvent,
    Goal,
    RejectedEvent,
    ThreatUpdate,
    UnitState,
    decode_direction,
    decode_event,
    decode_goal,
    encode,
    keys,
)
from pfp_service.world.world import (
    Deliberated,
    GoalSet,
    InputRejected,
    MissionRestored,
    StateReported,
    ThreatPut,
    Tick,
    World,
    WorldSettings,
)

pytestmark = pytest.mark.unit

INNOCENTS = [f"i{k}" for k in range(20)]
THREAT = ThreatUpdate(position=(5.0, 6.0), facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7)

# The bad unit sits at the origin and sends these goals (issue 21's list).
POISON = {
    "subnormal offset": {"position": [5e-324, 5e-324]},
    "subnormal step": {"position": [10.0, 10.0], "step": 5e-324},
    "subnormal tolerance": {"position": [10.0, 10.0], "tolerance": 5e-324},
    "subnormal delta": {"position": [10.0, 10.0], "delta": 5e-324},
    "goal on the unit": {"position": [0.0, 0.0]},
    "offset of 1e-300": {"position": [1e-300, 1e-300]},
}


def _goal_input(unit: str, body: dict) -> GoalSet | InputRejected:
    """What the node makes of a goal payload: the decoded goal, or its refusal."""
    key = keys.unit_goal(keys.DEFAULT_MISSION, unit)
    try:
        return GoalSet(unit, decode_goal(json.dumps(body).encode()))
    except InputError as err:
        return InputRejected(key, err)


def _states(t: float) -> list[StateReported]:
    return [
        StateReported(u, UnitState(position=(float(k), -3.0), seq=int(t * 10)))
        for k, u in enumerate(INNOCENTS)
    ]


def _valid(out) -> None:
    for d in out.directions:
        decode_direction(encode(d))
    for e in out.events:
        decode_event(encode(e))


@pytest.mark.parametrize("poison", list(POISON), ids=list(POISON))
def test_a_poison_goal_costs_no_innocent_unit_a_direction(poison):
    w = World(WorldSettings(planner=PlannerParams(intensity="density", delta=0.08)))
    w.apply([ThreatPut("e1", THREAT), *[GoalSet(u, Goal(position=(10.0, 12.0))) for u in INNOCENTS]], 0.0)
    answered = 0
    rejected: list[RejectedEvent] = []
    bad_status = set()
    for tick in range(20):  # 2 s at 10 Hz: the bad unit sends its goal with every report
        t = tick / 10
        bad = [StateReported("bad", UnitState(position=(0.0, 0.0))), _goal_input("bad", POISON[poison])]
        out = w.apply([*bad, *_states(t), Tick(t)], t)
        _valid(out)
        got = {d.unit for d in out.directions}
        answered += sum(u in got for u in INNOCENTS)
        rejected += [e for e in out.events if isinstance(e, RejectedEvent)]
        bad_status |= {d.status for d in out.directions if d.unit == "bad"}
    assert answered == 20 * len(INNOCENTS)  # every innocent unit, every tick
    assert w.counts()["faults"] == 0  # refused or planned as values: nothing failed inside
    if poison.startswith("subnormal") and poison != "subnormal offset":
        field = "$." + poison.split()[1]
        assert rejected and {(e.key, e.field) for e in rejected} == {
            (keys.unit_goal("default", "bad"), field)
        }
        assert "must be >=" in rejected[0].reason
        assert len(rejected) <= 2 * 5  # rate-limited: 5 a second per kind of key, the rest counted
        assert bad_status == {DirectionStatus.NO_GOAL}
    else:  # closer than the planner resolves, or exactly on it: arrived
        assert not rejected and bad_status == {DirectionStatus.ARRIVED}


def test_a_step_too_fine_for_the_distance_is_refused_with_its_path_and_a_close_goal_has_arrived():
    w = World()
    out = w.apply(
        [
            StateReported("u", UnitState(position=(0.0, 0.0))),
            GoalSet("u", Goal(position=(1e5, 0.0), step=1e-3)),
        ],
        0.0,
    )
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert (ev.key, ev.field) == (keys.unit_goal("default", "u"), "$.step")
    assert "needs 1e+08 steps" in ev.reason and "max_iter (1,000,000)" in ev.reason
    (d,) = out.directions
    assert d.status is DirectionStatus.NO_GOAL and d.reason.startswith(
        "goal refused: a step of 0.001 m needs 1e+08 steps"
    )
    out = w.apply([GoalSet("u", Goal(position=(5e-4, 0.0), step=1e-3))], 0.1)  # within 0.75 of a step
    assert [d.status for d in out.directions] == [DirectionStatus.ARRIVED]
    assert not [e for e in out.events if isinstance(e, RejectedEvent)]
    out = w.apply([GoalSet("u", Goal(position=(3e-4, 0.0)))], 0.2)  # derived: a step of 1 mm at least
    assert [d.status for d in out.directions] == [DirectionStatus.ARRIVED]


def test_an_input_that_fails_inside_is_rejected_alone_and_logged_once_a_minute_per_key():
    # no decoder lets a non-finite position through; a struct built in process can carry one
    broken = ThreatUpdate(position=(math.nan, 0.0), sigma_range=1.0, sigma_lateral=1.0)
    w = World(WorldSettings(planner=PlannerParams(intensity="density", delta=0.08)))
    w.apply([GoalSet(u, Goal(position=(10.0, 12.0))) for u in INNOCENTS], 0.0)
    out = w.apply([ThreatPut("bad", broken), ThreatPut("e1", THREAT), *_states(0.0)], 0.0)
    _valid(out)
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert ev.key == keys.threat("default", "bad") and "ValueError" in ev.reason
    assert "this input alone was dropped" in ev.reason
    assert {d.unit for d in out.directions} == set(INNOCENTS)  # and the good threat is in force
    assert w.counts()["threats"] == 1 and w.counts()["faults"] == 1
    (f,) = out.faults
    assert (f.key, f.error, f.suppressed) == (ev.key, "ValueError", 0) and f.where.endswith(
        ".py:" + f.where.split(":")[-1]
    )
    for t in range(1, 60):  # the same key again and again: rejected (rate-limited), logged no more
        out = w.apply([ThreatPut("bad", broken), *_states(t)], float(t))
        assert not out.faults and len(out.directions) == len(INNOCENTS)
    out = w.apply([ThreatPut("bad", broken)], 60.0)
    (f,) = out.faults
    assert f.suppressed == 59 and w.counts()["faults"] == 61


def test_a_corrupt_deliberation_result_drops_its_unit_alone():
    w = World(WorldSettings(deliberation="deferred", planner=PlannerParams(intensity="density", delta=0.08)))
    w.apply([ThreatPut("e1", THREAT)], 0.0)
    out = w.apply([*_states(0.0), *[GoalSet(u, Goal(position=(10.0, 12.0))) for u in INNOCENTS]], 0.0)
    jobs = {j.unit: j for j in out.jobs}
    assert set(jobs) == set(INNOCENTS)  # each asked for its look-ahead
    results = [jobs[u].run(0.0) for u in INNOCENTS]
    garbage = Deliberated("i3", jobs["i3"].token, "not a stepper")  # type: ignore[arg-type]
    out = w.apply([garbage, *results[4:], *_states(0.1)], 0.1)
    _valid(out)
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert ev.key == keys.unit_goal("default", "i3") and "AttributeError" in ev.reason
    status = {d.unit: d.status for d in out.directions}
    assert status["i3"] is DirectionStatus.NO_GOAL  # its goal dropped, told so
    assert all(status[u] is not DirectionStatus.NO_GOAL for u in INNOCENTS if u != "i3")


def test_a_unit_whose_numbers_break_the_vectorised_step_is_dropped_alone():
    w = World(WorldSettings(deliberation="deferred", planner=PlannerParams(intensity="density", delta=0.08)))
    w.apply([ThreatPut("e1", THREAT)], 0.0)
    out = w.apply([*_states(0.0), *[GoalSet(u, Goal(position=(10.0, 12.0))) for u in INNOCENTS]], 0.0)
    jobs = {j.unit: j for j in out.jobs}
    # a look-ahead answer that adopts cleanly but carries a route that is garbage (a damaged worker's):
    # the batch of every unit's descent raises on it, so the batch is run again one unit at a time
    done = jobs["i7"].run(0.0)
    done.stepper._run = "garbage"
    out = w.apply([done, *_states(0.1)], 0.1)
    _valid(out)
    status = {d.unit: d.status for d in out.directions}
    assert set(status) == set(INNOCENTS)
    assert status["i7"] is DirectionStatus.NO_GOAL
    assert all(s is not DirectionStatus.NO_GOAL for u, s in status.items() if u != "i7")
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert ev.key == keys.unit_goal("default", "i7") and "AttributeError" in ev.reason
    (f,) = out.faults
    assert f.where.startswith("core/")  # it failed in the step, not where the answer was taken


def test_a_restored_mission_with_numbers_no_plan_can_use_is_refused():
    nan = math.nan
    w = World()
    params = Resolved(nan, nan, 100, nan, "peak", "auto", 20, 200, 0)  # a damaged row: json reads NaN
    out = w.apply([MissionRestored("r", Goal(position=(5.0, 5.0)), (0.0, 0.0), params)], 0.0)
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert ev.key == keys.unit_goal("default", "r") and "cannot plan" in ev.reason
    assert w.counts()["faults"] == 0


def test_restored_units_are_stale_until_they_report_and_forgotten_on_the_usual_clock():
    w = World(WorldSettings(unit_stale_s=2.0, unit_forget_s=3.0))
    params = Resolved(0.08, 0.1, 300, 0.075, "peak", "auto", 20, 200, 0)
    restored = [
        *[MissionRestored(f"r{k}", Goal(position=(10.0, 10.0)), (0.0, 0.0), params) for k in range(57)],
        GoalSet("g", Goal(position=(3.0, 3.0))),  # a goal restored before its mission was fixed
        MissionRestored("back", Goal(position=(10.0, 10.0)), (0.0, 0.0), params),
    ]
    w.apply(restored, 0.0)
    assert w.counts()["units"] == 59 and w.counts()["units_stale"] == 59  # stale at once, not after 2 s
    out = w.apply([StateReported("back", UnitState(position=(1.0, 1.0))), Tick(1.0)], 1.0)
    (d,) = out.directions  # a unit that reports is fresh and guided by its restored mission
    assert d.unit == "back" and d.status is DirectionStatus.EN_ROUTE and w.counts()["units_stale"] == 58
    assert not [e for e in w.apply([Tick(2.99)], 2.99).events if isinstance(e, ForgottenEvent)]
    out = w.apply([StateReported("back", UnitState(position=(1.5, 1.5))), Tick(3.0)], 3.0)
    gone = {e.unit for e in out.events if isinstance(e, ForgottenEvent)}
    assert gone == {f"r{k}" for k in range(57)} | {"g"}  # forgotten unit_forget_s after the restore
    assert w.counts()["units"] == 1 and w.counts()["units_stale"] == 0
    assert not [e for e in out.events if isinstance(e, ArrivedEvent)]


def test_a_mission_of_a_denormal_step_deliberates_at_a_step_it_can_afford():
    # a peer's or a restored mission may carry a step of 2.2e-308 m when its tolerance covered the distance
    # then; from 100 m away its look-ahead once overflowed (6 * 100 / 2.2e-308 steps) in the worker: it is
    # now simulated, and its route kept, at a step the look-ahead's budget covers (foresight.resolution)
    params = Resolved(1.0, 2.2250738585072014e-308, 300, 10.0, "peak", "auto", 20, 200, 0)
    w = World(WorldSettings(deliberation="deferred", planner=PlannerParams(intensity="density", delta=0.08)))
    w.apply([MissionRestored("odd", Goal(position=(5.0, 0.0)), (0.0, 0.0), params)], 0.0)
    out = w.apply([StateReported("odd", UnitState(position=(100.0, 0.0)))], 0.0)
    results = [job.run(0.0) for job in out.jobs]
    assert [r.error for r in results] == [None]
    out = w.apply([*results, StateReported("odd", UnitState(position=(100.0, 0.0)))], 0.1)
    (d,) = [d for d in out.directions if d.unit == "odd"]
    assert d.status is DirectionStatus.EN_ROUTE and d.route == "descent" and d.vector[0] < -0.99


def test_a_deliberation_that_fails_where_it_runs_costs_its_unit_the_goal_and_no_one_else_anything(
    monkeypatch,
):
    # a look-ahead that raises in the worker (injected: no field this planner accepts makes it raise now)
    from pfp_service.core import foresight

    real = foresight.simulate

    def simulate(field, start, *args, **kwargs):
        if start == (100.0, 0.0):
            raise OverflowError("injected")
        return real(field, start, *args, **kwargs)

    monkeypatch.setattr(foresight, "simulate", simulate)
    w = World(WorldSettings(deliberation="deferred", planner=PlannerParams(intensity="density", delta=0.08)))
    w.apply([GoalSet("odd", Goal(position=(5.0, 0.0)))], 0.0)
    w.apply([GoalSet(u, Goal(position=(10.0, 12.0))) for u in INNOCENTS], 0.0)
    out = w.apply([StateReported("odd", UnitState(position=(100.0, 0.0))), *_states(0.0)], 0.0)
    results = [job.run(0.0) for job in out.jobs]  # as a worker runs them: an answer saying so, never a raise
    (failed,) = [r for r in results if r.error is not None]
    assert failed.unit == "odd" and failed.error[0] == "OverflowError"
    out = w.apply([*results, StateReported("odd", UnitState(position=(100.0, 0.0))), *_states(0.1)], 0.1)
    _valid(out)
    status = {d.unit: d.status for d in out.directions}
    assert status["odd"] is DirectionStatus.NO_GOAL
    assert all(status[u] is not DirectionStatus.NO_GOAL for u in INNOCENTS)
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert ev.key == keys.unit_goal("default", "odd") and "OverflowError" in ev.reason
    (f,) = out.faults
    assert f.error == "OverflowError" and f.where.startswith("test_world_bulkheads")  # where it raised
