"""Our clients' states name the unit's mobility class (issue 32): a team file's, ``pfp fleet --mobility``'s,
a scenario's ``unit:`` block's, the handheld's ``foot``; a bad one is refused naming the file, line and field."""

from __future__ import annotations

import pytest
from pfp_clients.fleet import FleetOptions
from pfp_clients.live_scenario import live_scenario

from pfp_service.errors import InputError
from pfp_service.team import load_team
from pfp_service.wire import GoalMobility, encode
from pfp_service.world.kinds import decode_state
from tests.conftest import run_pfp

TEAM = """\
name: mixed
units:
  - {id: truck, start: [0, 0], goal: [100, 0], mobility: {class: wheeled, max_slope_deg: 20}}
  - {id: tank, start: [0, 10], goal: [100, 10], mobility: {class: tracked}}
  - {id: rifle, kind: manned, start: [0, 20], goal: [100, 20]}
"""


@pytest.mark.unit
def test_a_team_files_classes_go_on_every_state_and_the_fleets_on_the_rest(tmp_path):
    p = tmp_path / "team.yaml"
    p.write_text(TEAM)
    team = load_team(p)
    for fleet_class, rifle in ((None, None), (GoalMobility(kind="foot"), GoalMobility(kind="foot"))):
        units = {u.id: FleetOptions(mobility=fleet_class).unit(u) for u in team.units}
        got = {uid: (u.state(0.0), u.state(0.2)) for uid, u in units.items()}
        assert (
            got["truck"][0].mobility
            == got["truck"][1].mobility
            == GoalMobility(kind="wheeled", max_slope_deg=20.0)
        )
        assert got["tank"][1].mobility == GoalMobility(kind="tracked")
        assert got["rifle"][1].mobility == rifle
        for first, second in got.values():  # as the planner's own decoder reads them
            assert decode_state(encode(second), None, None).mobility == second.mobility


@pytest.mark.unit
@pytest.mark.parametrize(
    ("mobility", "field", "reason"),
    [
        ("{class: hovercraft}", "units[0].mobility.class", "foot, wheeled, tracked"),
        ("{class: foot, max_slope_deg: 10}", "units[0].mobility.max_slope_deg", ">= 17"),
        ("{kind: foot}", "units[0].mobility.kind", "unknown field"),
    ],
)
def test_a_bad_class_in_a_team_file_is_refused_naming_the_line_and_field(tmp_path, mobility, field, reason):
    p = tmp_path / "team.yaml"
    p.write_text(f"units:\n  - {{id: u, start: [0, 0], mobility: {mobility}}}\n")
    with pytest.raises(InputError) as got:
        load_team(p)
    assert got.value.path == f"team.yaml line 2, {field}", got.value
    assert reason in got.value.reason, got.value


@pytest.mark.unit
def test_a_scenarios_unit_block_goes_live_on_its_states(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text("start: [0, 0]\ngoal: [100, 0]\nunit: {class: tracked, max_slope_deg: 25}\n")
    (unit,) = live_scenario(f).team.units
    assert FleetOptions().unit(unit).state(0.0).mobility == GoalMobility(kind="tracked", max_slope_deg=25.0)
    f.write_text("start: [0, 0]\ngoal: [100, 0]\n")  # no block: a soldier, as pfp plan plans it
    (unit,) = live_scenario(f).team.units
    assert FleetOptions().unit(unit).state(0.0).mobility == GoalMobility(kind="foot")
    f.write_text("start: [0, 0]\ngoal: [100, 0]\nunit: {class: wheeled, max_slope_deg: 10}\n")
    with pytest.raises(InputError) as got:
        live_scenario(f)
    assert got.value.path == "s.yaml, unit.max_slope_deg" and "17" in got.value.reason


@pytest.mark.proc
def test_pfp_fleet_refuses_an_unknown_mobility_in_one_line_and_exit_2():
    r = run_pfp("fleet", "--generate", "2", "--mobility", "hovercraft", "--duration-s", "1")
    assert r.returncode == 2 and "--mobility" in r.stderr and "Traceback" not in r.stderr
