"""``pfp inject SCENARIO.yaml``: one document, plan or live -- a scenario file runs live and follows its plan."""

from __future__ import annotations

import re
import uuid

import numpy as np
import pytest
from pfp_clients.live_scenario import deviation_m, is_scenario_file, live_scenario
from pfp_clients.script import AddThreat, SetGoal

from pfp_service.errors import InputError
from pfp_service.world import translate
from tests.conftest import EXAMPLES, run_pfp
from tests.zenoh_util import planner_process

GEO = EXAMPLES / "geo-simple.yaml"


@pytest.mark.unit
def test_a_scenario_is_told_from_a_script():
    assert is_scenario_file(GEO)
    assert is_scenario_file(EXAMPLES / "paper-simple.yaml")
    assert not is_scenario_file(EXAMPLES / "demo-inject.yaml")
    assert not is_scenario_file(EXAMPLES / "demo-team.yaml")


@pytest.mark.unit
def test_a_scenario_becomes_threats_a_goal_and_a_unit():
    ls = live_scenario(GEO, "scout-1", rate_hz=4.0)
    adds = [s for s in ls.script.timeline if isinstance(s, AddThreat)]
    assert [a.threat for a in adds] == ["ridge", "farm", "wood"]
    assert np.allclose(adds[0].position, (700, 800), atol=0.05)  # {lat, lon} became metres from the origin
    assert adds[0].sigma_range == 120 and adds[0].skew == 2
    goal = ls.script.timeline[-1]
    assert isinstance(goal, SetGoal) and goal.unit == "scout-1"
    assert np.allclose(goal.position, (1800, 1400), atol=0.05)
    assert goal.step is not None and ls.team.units[0].speed_mps == pytest.approx(goal.step * 4.0)
    assert ls.script.origin == ls.scenario.origin == ls.team.origin
    assert ls.plan_status == "reached" and ls.tolerance_m == pytest.approx(goal.tolerance)


@pytest.mark.unit
def test_a_threat_that_appears_later_is_put_at_its_tick(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text(
        "start: [0, 0]\ngoal: [100, 0]\nthreats:\n"
        "  - {id: a, position: [50, 10], sigma_range: 5, sigma_lateral: 4, appear_step: 20}\n"
    )
    ls = live_scenario(f, rate_hz=5.0)
    assert ls.script.timeline[0].at_s == pytest.approx(4.0)


@pytest.mark.unit
def test_the_raw_threat_form_cannot_go_live_and_says_where(tmp_path):
    f = tmp_path / "raw.yaml"
    f.write_text(
        "start: [0, 0]\ngoal: [10, 10]\nthreats:\n"
        "  - {position: [5, 5], omega: [[1, 0], [0, 1]], alpha: [0, 0]}\n"
    )
    with pytest.raises(InputError) as e:
        live_scenario(f)
    assert str(e.value).startswith("raw.yaml, threats[0].omega: the raw form")


@pytest.mark.unit
def test_deviation_is_zero_on_the_same_path_and_sees_a_detour():
    line = np.array([(0.0, 0.0), (10.0, 0.0), (20.0, 0.0)])
    assert deviation_m(line, line) == 0.0
    dense = np.column_stack([np.linspace(0, 20, 41), np.zeros(41)])
    assert deviation_m(dense, line) == pytest.approx(0.0, abs=1e-12)
    bent = dense.copy()
    bent[20, 1] = 3.0
    assert deviation_m(bent, line) == pytest.approx(3.0)


@pytest.mark.proc
def test_pfp_inject_a_scenario_runs_live_and_follows_its_plan():
    mission = "s" + uuid.uuid4().hex[:10]
    with planner_process("--origin", "58.4105,15.6213,90", mission=mission) as (endpoint, _):
        r = run_pfp(
            "inject", str(GEO), "--connect", endpoint, "--mission", mission, "--speed-up", "20", timeout=180
        )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "add threat ridge" in r.stdout and "set goal of u1" in r.stdout
    assert "PASS  u1 arrives within" in r.stdout
    m = re.search(
        r"PASS  live track of u1 follows the plan within ([\d.e+-]+) m: largest deviation ([\d.e+-]+) m",
        r.stdout,
    )
    assert m, r.stdout[-2000:]
    assert float(m.group(2)) <= float(m.group(1))


@pytest.mark.proc
def test_pfp_inject_a_scenario_against_a_planner_of_another_intensity_fails_honestly():
    """The paper's scenario plans with the raw density; a planner on peak walks another path, and says so."""
    mission = "s" + uuid.uuid4().hex[:10]
    with planner_process(mission=mission) as (endpoint, _):
        r = run_pfp(
            "inject", str(EXAMPLES / "paper-simple.yaml"), "--connect", endpoint, "--mission", mission,
            "--speed-up", "20", timeout=180,
        )  # fmt: skip
    assert "FAIL  live track of u1 follows the plan" in r.stdout, r.stdout[-2000:]
    assert r.returncode == 1


ZONED = """\
name: zoned
start: [0, 0]
goal: [100, 0]
threats:
  - {id: e1, position: [50, 25], facing_deg: 180, sigma_range: 8, sigma_lateral: 6}
zones:
  - {id: wall, polygon: [[[40, -20], [60, -20], [60, -0.5], [40, -0.5], [40, -20]]]}
"""


@pytest.mark.unit
def test_a_scenario_zone_goes_live_with_an_expectation_to_keep_out(tmp_path):
    from pfp_clients.script import AddZone

    f = tmp_path / "zoned.yaml"
    f.write_text(ZONED)
    ls = live_scenario(f)
    zones = [s for s in ls.script.timeline if isinstance(s, AddZone)]
    assert [z.zone for z in zones] == ["wall"]
    assert any(e.never_enters == "wall" for e in ls.script.expect)
    assert ls.plan_status == "reached"
    # the plan itself goes round the wall
    from pfp_service.core.zones import track_enters

    wall = [translate.zone(zones[0].update(), "wall")]
    assert track_enters(wall, ls.plan_path) is None
    from pfp_service.core import plan

    sc = ls.scenario  # without the zone, the threat would push the path into it
    free = plan(sc.start, sc.goal, sc.schedule(), sc.planner.to_params())
    assert track_enters(wall, np.asarray(free.path)) == "wall"


@pytest.mark.unit
def test_never_enters_sees_a_track_that_crosses_a_zone_and_one_that_does_not():
    from pfp_clients.expectations import ZoneVersion, judge
    from pfp_clients.script import AddZone, Expect
    from pfp_clients.watch import Watch

    from pfp_service.wire.messages.structs import ZoneCircle

    zone = translate.zone(AddZone(zone="z", circle=ZoneCircle(centre=(5.0, 0.0), radius_m=1.0)).update(), "z")
    e = Expect(unit="u", never_enters="z")
    through, past = Watch(), Watch()
    for i in range(11):
        through.on_state("u", (float(i), 0.5 if i == 5 else 2.0), float(i))  # one point inside
        past.on_state("u", (float(i), 1.5), float(i))
    fast = Watch()  # two states either side: only the segment between them crosses it
    fast.on_state("u", (3.0, 0.0), 0.0)
    fast.on_state("u", (7.0, 0.0), 1.0)
    versions = [ZoneVersion("z", zone, 0.0)]
    assert not judge(e, through, versions).held
    assert "entered zone z at (5.00, 0.50)" in judge(e, through, versions).detail
    assert judge(e, past, versions).held
    assert not judge(e, fast, versions).held
    # a zone put after the unit went by is not held against it
    assert judge(e, through, [ZoneVersion("z", zone, 20.0)]).detail.endswith("was in force")
    assert not judge(e, past, []).held  # never put: nothing was checked, so it did not hold


@pytest.mark.proc
def test_pfp_inject_a_scenario_with_a_zone_keeps_out_of_it_live(tmp_path):
    f = tmp_path / "zoned.yaml"
    f.write_text(ZONED)
    mission = "s" + uuid.uuid4().hex[:10]
    with planner_process(mission=mission) as (endpoint, _):
        r = run_pfp(
            "inject", str(f), "--connect", endpoint, "--mission", mission, "--speed-up", "20", timeout=180
        )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "add zone wall" in r.stdout
    assert re.search(r"PASS  u1 never enters zone wall: \d+ track segments checked", r.stdout), r.stdout[
        -2000:
    ]
    assert "PASS  live track of u1 follows the plan" in r.stdout
