"""Look-ahead: ``auto`` simulates its own descent once per goal or world change and goes round a foreseen trap."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks._cases import generate
from pfp_service.core import PlannerParams, Scheduled, Threat, ThreatField, foresight, plan, resolve
from pfp_service.core.batch import advise_many
from pfp_service.core.cores import Cores
from pfp_service.core.optimal import plan_optimal
from pfp_service.core.stepper import Stepper, StepStatus

pytestmark = pytest.mark.unit

START, GOAL = (0.0, 0.0), (100.0, 100.0)


def horseshoe():  # as in test_escape: open towards the start, its back to the goal
    out = []
    for k in range(9):
        b = math.radians(-55 + 200 * k / 8)
        xy = (60 + 12 * math.sin(b), 60 + 12 * math.cos(b))
        out.append(Threat.from_facing(xy, 225, 4.0, 4.0, 0.5, 1.0, f"h{k}"))
    return out


def cup():  # three straight walls
    pts = [(70 + 5 * k * 0.7071 - 15 * 0.7071, 70 - 5 * k * 0.7071 + 15 * 0.7071) for k in range(7)]
    for end in (pts[0], pts[-1]):
        pts += [(end[0] - 5 * j * 0.7071, end[1] - 5 * j * 0.7071) for j in (1, 2, 3)]
    return [Threat.from_facing(p, 225, 4, 4, 0.3, 1.0, f"c{i}") for i, p in enumerate(pts)]


def block():
    return [Threat.from_facing((50, 50), 225, 6, 6, 0.0, 1.0, "b")]


def _plan(threats, escape):
    return plan(START, GOAL, [Scheduled(t) for t in threats], PlannerParams(escape=escape))


def _core_entry(threats, path):
    return Cores(ThreatField(threats)).first_hit(np.asarray(path))


@pytest.mark.parametrize("seed", [3, 17])
def test_simulation_mirrors_plain_descent_step_for_step(seed):
    outcome = {"reached": foresight.Outcome.ARRIVES, "trapped": foresight.Outcome.TRAPPED}
    for case in generate(8, seed):
        threats = [Scheduled(t) for t in case.threats]
        params = resolve(PlannerParams(escape="none"), case.start, case.goal, case.threats)
        r = plan(case.start, case.goal, threats, params)
        d0sq = math.dist(case.start, case.goal) ** 2
        sim = foresight.simulate(
            ThreatField(case.threats), case.start, case.goal, params.delta / d0sq, params
        )
        assert sim.outcome is outcome[r.status.value], (seed, case.name)
        assert sim.steps == r.steps, (seed, case.name)  # the position agrees to rounding (FMA)
        assert math.dist((sim.x, sim.y), r.path[-1]) <= 1e-9 * math.dist(case.start, case.goal)


@pytest.mark.parametrize("make", [horseshoe, cup, block], ids=["horseshoe", "cup", "block"])
def test_auto_goes_round_a_foreseen_trap_from_the_first_step(make):
    threats = make()
    field = ThreatField(threats)
    params = resolve(PlannerParams(escape="auto"), START, GOAL, threats)
    first = Stepper(START, GOAL, params).advise(field, *START)
    assert first.status is StepStatus.ESCAPING and "trapped foreseen" in first.reason
    r = _plan(threats, "auto")
    assert r.status.value == "reached" and r.escapes == ["global"] and r.traps == 1
    assert not _core_entry(threats, r.path)
    # near the optimum of the same cost: within 5 % of its J at lambda 10
    opt = plan_optimal(START, GOAL, [Scheduled(t) for t in threats], 10.0, cells=150)
    assert r.length + 10.0 * r.exposure <= 1.05 * (opt.length + 10.0 * opt.exposure)


def test_look_ahead_runs_once_per_goal_and_per_world_change(monkeypatch):
    calls = []
    real = foresight.simulate

    def counting(*args, **kw):
        calls.append(args[1])
        return real(*args, **kw)

    monkeypatch.setattr(foresight, "simulate", counting)
    late = Threat.from_facing((90.0, 10.0), 0, 3, 3, 0.0, 1.0, "late")
    sched = [Scheduled(t) for t in horseshoe()] + [Scheduled(late, appear_step=5)]
    r = plan(START, GOAL, sched, PlannerParams(escape="auto"))
    assert r.status.value == "reached" and len(calls) == 2 and calls[0] == START
    calls.clear()
    plan(START, GOAL, sched, PlannerParams(escape="none"))
    assert calls == []  # plain descent never looks ahead


def test_advise_many_looks_ahead_like_advise_and_then_stays_lean(monkeypatch):
    threats = horseshoe()
    field = ThreatField(threats)
    params = resolve(PlannerParams(escape="auto"), START, GOAL, threats)
    lone = Stepper(START, GOAL, params)
    batch = [Stepper(START, GOAL, params), Stepper((100.0, 0.0), GOAL, params)]
    pos = np.array([START, (100.0, 0.0)])
    first = advise_many(batch, field, pos)
    assert first[0] == lone.advise(field, *START)
    monkeypatch.setattr(foresight, "simulate", lambda *a, **k: pytest.fail("looked ahead twice"))
    for _ in range(5):
        advise_many(batch, field, pos)


def test_a_threat_on_the_committed_route_is_seen_and_avoided():
    threats = horseshoe()
    r0 = _plan(threats, "auto")
    mid = r0.path[len(r0.path) // 2]
    blocker = Threat.from_facing(mid, 0, 3.0, 3.0, 0.0, 1.0, "blocker")
    sched = [Scheduled(t) for t in threats] + [Scheduled(blocker, appear_step=len(r0.path) // 4)]
    r = plan(START, GOAL, sched, PlannerParams(escape="auto"))
    assert r.status.value == "reached" and r.final_distance <= r.params.tolerance
    assert not _core_entry([*threats, blocker], r.path[len(r0.path) // 4 :])


def test_look_ahead_is_bounded_and_a_step_too_fine_for_it_is_simulated_coarser():
    import time

    threat = Threat.from_facing((5e4, 3.0), 0.0, 10.0, 10.0, 0.0)
    params = resolve(PlannerParams(step=1e-4), (0.0, 0.0), (1e5, 0.0), [threat])
    field = ThreatField([threat])
    sim = foresight.simulate(field, (0.0, 0.0), (1e5, 0.0), params.delta / 1e10, params)
    # a billion steps of 0.1 mm do not fit the budget: the same descent at 20 m does, and arrives
    assert sim.outcome is foresight.Outcome.ARRIVES and sim.step == 20.0
    assert sim.steps <= foresight.FORESIGHT_MAX_STEPS
    cut = foresight.simulate(field, (0.0, 0.0), (1e5, 0.0), params.delta / 1e10, params, budget=100)
    assert cut.outcome is foresight.Outcome.RUNS_ON and cut.steps == 100  # cut short: foresees nothing
    stepper = Stepper((0.0, 0.0), (1e5, 0.0), params)
    t0 = time.perf_counter()
    advice = stepper.advise(field, 0.0, 0.0)
    assert time.perf_counter() - t0 < 2.0
    assert advice.status is StepStatus.EN_ROUTE and stepper.traps == 0
