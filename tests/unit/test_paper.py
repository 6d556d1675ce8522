"""The paper's experiments, reproduced (Sung, Kim & Cho 2023, Table 1, Figures 8 and 9)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import PlanStatus, Scheduled, plan
from pfp_service.scenario import load_scenario
from tests.conftest import EXAMPLES

pytestmark = pytest.mark.unit


def _plan(scn, **over):
    params = scn.planner.to_params().merged(**over)
    return plan(scn.start, scn.goal, scn.schedule(), params, scn.bounds_tuple())


def test_table_1_reaches_within_300_steps(paper_scenario):
    r = _plan(paper_scenario)
    assert r.params.delta == 0.08 and r.params.step == 0.1 and r.params.max_iter == 300
    assert r.params.intensity == "density"
    assert r.status is PlanStatus.REACHED
    assert r.steps <= 300
    assert r.final_distance <= 0.1
    # it went around the threats, not through them
    assert r.min_clearance is not None and r.min_clearance > 1.5


def test_figure_9_large_delta_passes_closer(paper_scenario):
    base = _plan(paper_scenario)
    bold = _plan(paper_scenario, delta=2.0)
    assert bold.status is PlanStatus.REACHED
    assert bold.min_clearance < base.min_clearance
    assert bold.exposure > base.exposure


def test_figure_9_tiny_delta_fails_and_says_so(paper_scenario):
    timid = _plan(paper_scenario, delta=0.01, escape="none")  # plain descent, as in the paper
    assert timid.status is not PlanStatus.REACHED
    assert timid.status is PlanStatus.TRAPPED
    assert timid.final_distance > 0.1
    assert timid.steps < 300  # detected, not run out silently
    assert "oscillat" in timid.reason or "progress" in timid.reason


def test_figure_8_pop_up_bends_the_path():
    scn = load_scenario(EXAMPLES / "paper-contingency.yaml")
    with_popup = _plan(scn)
    popup = next(s for s in scn.schedule() if s.appear_step > 0)
    k = popup.appear_step
    undisturbed = plan(
        scn.start, scn.goal, [s for s in scn.schedule() if s.appear_step == 0], scn.planner.to_params()
    )
    a, b = np.array(with_popup.path), np.array(undisturbed.path)
    # identical until the enemy appears, different after
    np.testing.assert_array_equal(a[: k + 1], b[: k + 1])
    assert not np.allclose(a[k + 5 : k + 30], b[k + 5 : k + 30])
    # the new path keeps further from the new enemy, and still arrives
    e3 = np.array(popup.threat.xi)
    d_new = np.hypot(*(a[k:] - e3).T).min()
    d_old = np.hypot(*(b[k:] - e3).T).min()
    assert d_new > d_old
    assert with_popup.status is PlanStatus.REACHED
    assert with_popup.events and f"step {k}" in with_popup.events[0]


def test_pop_up_exposure_counts_only_after_appearance(paper_scenario):
    # the same threat, present from the start vs. appearing after the unit has passed it
    late = [*paper_scenario.schedule()]
    t = late[0].threat
    early_r = plan((0, 0), (10, 10), [Scheduled(t, 0)], paper_scenario.planner.to_params())
    never_r = plan((0, 0), (10, 10), [Scheduled(t, 10_000)], paper_scenario.planner.to_params())
    assert early_r.exposure > 0
    assert never_r.exposure == 0.0
    assert never_r.min_clearance is None


def test_peak_defaults_reach_the_paper_instance(paper_scenario):
    # the scale-free defaults (no delta/step given, peak intensity) also solve Table 1
    r = plan(paper_scenario.start, paper_scenario.goal, paper_scenario.schedule())
    assert r.status is PlanStatus.REACHED
    assert r.params.intensity == "peak"
    assert r.min_clearance > 1.5
    assert math.isclose(r.params.step, math.hypot(10, 10) / 150)


@pytest.mark.parametrize("delta", [0.08, 0.2])
def test_table_2_range_reaches(paper_scenario, delta):
    assert _plan(paper_scenario, delta=delta).status is PlanStatus.REACHED
