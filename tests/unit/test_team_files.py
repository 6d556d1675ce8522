"""Team files' and scenarios' ``teams:``: read with their roles, and each clash refused naming the file, line and field."""

from __future__ import annotations

import pytest

from pfp_service.errors import InputError
from pfp_service.scenario import load_scenario
from pfp_service.team import load_team
from tests.conftest import run_pfp

UNITS = """\
name: squad
units:
  - {id: m1, kind: manned, start: [0, 10], goal: [200, 10]}
  - {id: m2, kind: manned, start: [0, 20], goal: [200, 20]}
  - {id: r1, kind: unmanned, start: [10, 15], goal: [200, 15]}
  - {id: r2, kind: unmanned, start: [5, 30], goal: [200, 30]}
teams:
"""
ALPHA = """\
  - id: alpha
    separation_m: 20
    lead: r1
    follow: [m1, m2]
    standoff_m: 30
    corridor_m: 6
    controller: m1
    robots: [r1, r2]
    radio_range_m: 80
"""


@pytest.mark.unit
def test_the_issue_s_team_file_is_read_with_its_roles(tmp_path):
    p = tmp_path / "team.yaml"
    p.write_text(UNITS + ALPHA)
    (team,) = load_team(p).teams
    assert (team.id, team.lead, team.follow, team.controller, team.robots) == (
        "alpha", "r1", ["m1", "m2"], "m1", ["r1", "r2"],
    )  # fmt: skip
    assert (team.standoff_m, team.corridor_m, team.radio_range_m, team.separation_m) == (30, 6, 80, 20)


@pytest.mark.unit
@pytest.mark.parametrize(
    ("teams", "where", "reason"),
    [
        ("  - {id: a, lead: r1, follow: [m9]}\n", "line 8, teams[0].follow[0]", "unknown unit 'm9'"),
        (
            "  - {id: a, lead: r1, follow: [m1]}\n  - {id: b, controller: m1, robots: [r2]}\n",
            "line 9, teams[1].controller",
            "already in team 'a'",
        ),
        (
            "  - {id: a, lead: r1, follow: [m1]}\n  - {id: b, lead: m1, follow: [r1]}\n",
            "line 9, teams[1].lead",
            "a cycle of leads",
        ),
        (
            "  - {id: a, controller: m1, robots: [m1]}\n",
            "line 8, teams[0].robots[0]",
            "cannot control itself",
        ),
        ("  - {id: a, lead: r1, follow: [m1, r1]}\n", "line 8, teams[0].follow[1]", "cannot follow itself"),
        ("  - {id: a, members: [m1]}\n  - {id: a, members: [m2]}\n", "line 9, teams[1].id", "duplicate id"),
        ("  - {id: a, lead: r1, standoff_m: -3}\n", "line 8, teams[0].standoff_m", "> 0"),
    ],
)
def test_a_bad_team_is_refused_naming_the_file_line_and_field(tmp_path, teams, where, reason):
    p = tmp_path / "team.yaml"
    p.write_text(UNITS + teams)
    with pytest.raises(InputError) as got:
        load_team(p)
    assert got.value.path == f"team.yaml {where}", got.value
    assert reason in got.value.reason


@pytest.mark.unit
def test_a_scenario_s_teams_are_checked_without_knowing_the_units(tmp_path):
    p = tmp_path / "s.yaml"
    head = "name: s\nstart: [0, 0]\ngoal: [10, 10]\nteams:\n"
    p.write_text(head + "  - {id: a, lead: s1, follow: [m7]}\n")
    assert load_scenario(p).teams[0].follow == ["m7"]
    p.write_text(head + "  - {id: a, lead: x, follow: [y]}\n  - {id: b, lead: y, follow: [x]}\n")
    with pytest.raises(InputError) as got:
        load_scenario(p)
    assert got.value.path == "s.yaml line 6, teams[1].lead"


@pytest.mark.proc
def test_pfp_fleet_refuses_a_bad_team_in_one_line_and_exit_2(tmp_path):
    p = tmp_path / "team.yaml"
    p.write_text(UNITS + "  - {id: a, controller: r1, robots: [r1]}\n")
    r = run_pfp("fleet", "--team", str(p), "--connect", "tcp/127.0.0.1:9", timeout=60)
    assert r.returncode == 2, r.stdout + r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert "team.yaml line 8, teams[0].robots[0]" in r.stderr and "cannot control itself" in r.stderr
