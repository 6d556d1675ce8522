"""One step rule (``steprule.judge``): plain descent's final approach lands on the goal, and every driver agrees.

The regression: on paper-scale variants (8 threats in 30 x 30, step 0.3,
tolerance 0.1, density intensity) plain descent moved a full step at the
goal too, bounced across it about 0.18 away and ended ``trapped`` (16 of the
40 seeds below, 12 of them within a step of the goal).  The last step now
ends on the goal, by the same rule for the stepper, the look-ahead, the
foresight and the route walkers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import (
    PlannerParams,
    PlanStatus,
    Scheduled,
    Stepper,
    ThreatField,
    foresight,
    plan,
    resolve,
    steprule,
)
from pfp_service.core.plan import predict_many, walk
from pfp_service.core.stepper import StepStatus
from tests.unit.test_route_arrival import GOAL, SIZE, START, _params, paper_scale_threats

pytestmark = pytest.mark.unit

SEEDS = range(40)


def test_plain_descent_ends_on_the_goal_instead_of_bouncing_beside_it():
    reached = 0
    for seed in SEEDS:
        r = plan(START, GOAL, [Scheduled(t) for t in paper_scale_threats(seed)], _params("none"))
        if r.status is PlanStatus.REACHED:
            reached += 1
            assert r.final_distance <= 0.1
        else:  # a real trap, not a bounce within a step of the goal
            assert r.status is PlanStatus.TRAPPED and r.final_distance > 0.3, (
                seed,
                r.reason,
                r.final_distance,
            )
    assert reached >= 30, reached  # was 24: the 12 bounces now arrive


def test_a_bounce_seen_before_now_lands_on_the_goal():
    r = plan(START, GOAL, [Scheduled(t) for t in paper_scale_threats(24)], _params("none"))
    assert r.status is PlanStatus.REACHED, r.reason  # was trapped 0.181 from the goal after 170 steps
    assert r.path[-1] == GOAL and math.dist(r.path[-2], GOAL) <= 0.3


def test_within_a_step_the_advice_heads_for_the_goal_and_its_step_ends_there():
    params = resolve(PlannerParams(step=1.0, tolerance=0.1, escape="none"), (0.0, 0.0), (10.0, 0.0))
    s = Stepper((0.0, 0.0), (10.0, 0.0), params)
    field = ThreatField([])
    far = s.advise(field, 5.0, 0.0)
    assert far.status is StepStatus.EN_ROUTE and far.reach == 1.0 and far.to == (6.0, 0.0)
    near = s.advise(field, 9.4, 0.3)
    assert near.status is StepStatus.EN_ROUTE and near.to == (10.0, 0.0)
    assert math.isclose(near.reach, math.hypot(0.6, 0.3))
    assert math.isclose(near.dx, 0.6 / near.reach) and math.isclose(near.dy, -0.3 / near.reach)
    assert s.advise(field, *near.to).status is StepStatus.ARRIVED
    assert s.step_along(9.4, 0.3, 0.0, 1.0) == (10.0, 0.0)  # a heading given, the same final approach


@pytest.mark.parametrize("trap_window", [20, 150])  # 150: the watch's ring grows past its first 64 places
def test_foresight_predict_and_the_stepper_walk_the_same_steps(trap_window):
    compared = 0
    for seed in SEEDS:
        threats = paper_scale_threats(seed)
        params = resolve(_params("none", trap_window=trap_window), START, GOAL, threats)
        r = plan(START, GOAL, [Scheduled(t) for t in threats], params)
        field = ThreatField(threats, params.intensity)
        gain = params.delta / math.dist(START, GOAL) ** 2
        sim = foresight.simulate(field, START, GOAL, gain, params)
        want = {"reached": foresight.Outcome.ARRIVES, "trapped": foresight.Outcome.TRAPPED}[r.status.value]
        assert sim.outcome is want and sim.steps == r.steps, (seed, sim, r.status, r.steps)
        assert math.dist((sim.x, sim.y), r.path[-1]) <= 1e-12 * SIZE, seed  # to rounding (FMA)
        # the batched look-ahead from each of the last 12 positions: the stepper's own next steps
        for k in range(max(0, len(r.path) - 12), len(r.path) - 1):
            (ahead,) = predict_many([Stepper(START, GOAL, params)], field, np.array([r.path[k]]), 11)
            n = min(len(ahead), len(r.path) - k)
            if r.status is PlanStatus.REACHED:  # the look-ahead stops on the goal too
                assert len(ahead) == len(r.path) - k, (seed, k)
            np.testing.assert_allclose(ahead[:n], r.path[k : k + n], rtol=0.0, atol=1e-12 * SIZE)
            compared += 1
    assert compared > 300


def test_a_walk_moves_to_where_the_advice_says_and_nowhere_else():
    params = resolve(PlannerParams(escape="none"), START, GOAL, paper_scale_threats(3))
    field = ThreatField(paper_scale_threats(3), params.intensity)
    s = Stepper(START, GOAL, params)
    track = [START]
    adv, moved = walk(s, field, track, 5)
    twin = Stepper(START, GOAL, params)
    x, y = START
    for k in range(moved):
        a = twin.advise(field, x, y)
        x, y = a.to
        assert track[k + 1] == (x, y)
    assert adv is None and moved == 5


def test_the_rule_judges_in_its_documented_order():
    u = steprule.unit((10.0, 0.0), 0.0, 0.5, 1.0, ((0.0, -1.0), (20.0, 1.0)), 3, 100)
    j = steprule.judge
    assert j(u, math.nan, 0.0, 1.0, 0.0, 1.0, steprule.DESCENT)[0] == steprule.BAD_POSITION
    assert j(u, 9.8, 0.0, math.nan, 0.0, math.nan, steprule.DESCENT)[0] == steprule.ARRIVED
    assert j(u, 5.0, 3.0, 1.0, 0.0, 1.0, steprule.DESCENT)[0] == steprule.OUT_OF_BOUNDS
    assert j(u, 5.0, 0.0, math.inf, 0.0, math.inf, steprule.DESCENT)[0] == steprule.BAD_GRADIENT
    assert j(u, 5.0, 0.0, 0.0, 0.0, 0.0, steprule.DESCENT)[0] == steprule.STATIONARY
    # oscillating: back and forth 0.1 across a point, three advisories apart
    codes = [j(u, 5.0 + 0.1 * (k % 2), 0.0, -1.0, 0.0, 1.0, steprule.DESCENT)[0] for k in range(4)]
    assert codes == [steprule.GO, steprule.GO, steprule.GO, steprule.OSCILLATING]
    steprule.reset_watch(u)
    assert j(u, 5.0, 0.0, -1.0, 0.0, 1.0, steprule.DESCENT)[0] == steprule.GO


def test_a_previews_first_move_takes_the_same_final_approach():
    # a live unit's last direction, taken without advising again (plan's first_move), lands on a goal within a step
    params = resolve(PlannerParams(step=1.0, tolerance=0.1, escape="none"), (0.0, 0.0), (10.0, 0.0))
    r = plan((9.4, 0.3), (10.0, 0.0), (), params, origin=(0.0, 0.0), first_move=(1.0, 0.0))
    assert r.path[:2] == [(9.4, 0.3), (10.0, 0.0)]
    assert r.status is PlanStatus.REACHED and r.steps == 1
