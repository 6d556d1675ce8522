"""A team on the wire: its bounds and its own checks as it decodes, and the checks across teams (``team_problems``)."""

from __future__ import annotations

import json

import pytest

from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.wire import messages as m

pytestmark = pytest.mark.unit


def _decode(doc: dict[str, object]) -> m.TeamUpdate:
    return m.decode_team(json.dumps(doc).encode())


def test_the_issue_s_team_decodes_with_its_roles() -> None:
    team = _decode(
        {"separation_m": 20, "lead": "r1", "follow": ["m1", "m2"], "standoff_m": 300, "corridor_m": 30}
        | {"controller": "m1", "robots": ["r1", "r2"], "radio_range_m": 1500}
    )
    assert team.units() == ("r1", "m1", "m2", "r2")
    assert team.roles("m1") == ("follow", "controller")
    assert team.roles("r1") == ("lead", "robot")
    assert team.roles("zz") == ()
    assert keys.team("alpha", "t1") == "mumt/alpha/team/t1"
    assert keys.parse("mumt/alpha/team/t1") == keys.Key(keys.KeyKind.TEAM, "alpha", "t1")


@pytest.mark.parametrize(
    ("doc", "path", "reason"),
    [
        ({"lead": "r1", "follow": ["m1", "r1"]}, "$.follow[1]", "cannot follow itself"),
        ({"controller": "m1", "robots": ["r1", "m1"]}, "$.robots[1]", "cannot control itself"),
        ({"follow": ["m1"]}, "$.follow", "need a lead"),
        ({"robots": ["r1"]}, "$.robots", "need a controller"),
        ({"members": ["a", "b", "a"]}, "$.members[2]", "listed twice"),
        ({"radio_range_m": 0}, "$.radio_range_m", "> 0"),
        ({"standoff_m": 1e12}, "$.standoff_m", "<= 100000"),
        ({"lead": "r/1"}, "$.lead", "matching regex"),
        ({"follow": [f"u{i}" for i in range(300)], "lead": "r"}, "$.follow", "length must be <= 256"),
    ],
)
def test_a_bad_team_is_refused_with_its_field(doc: dict[str, object], path: str, reason: str) -> None:
    with pytest.raises(InputError) as e:
        _decode(doc)
    assert e.value.path == path
    assert reason in e.value.reason


def _team(**kw: object) -> m.TeamUpdate:
    return m.TeamUpdate(**kw)  # type: ignore[arg-type]


def test_teams_that_agree_have_no_problem_and_a_chain_of_leads_is_allowed() -> None:
    teams = {
        "a": _team(lead="s1", follow=["s2"], controller="m1", robots=["r1"]),
        "b": _team(lead="s2", follow=["m2"]),  # s2 follows s1 in a and leads b
    }
    assert m.team_problems(teams, known={"s1", "s2", "m1", "r1", "m2"}) == []


@pytest.mark.parametrize(
    ("teams", "team", "path", "reason"),
    [
        ({"a": _team(lead="r1", follow=["m9"])}, "a", "follow[0]", "unknown unit 'm9'"),
        (
            {"a": _team(members=["m1"]), "b": _team(controller="m1", robots=["r1"])},
            "b",
            "controller",
            "already in team 'a'",
        ),
        (
            {"a": _team(lead="x", follow=["y"]), "b": _team(lead="y", follow=["x"])},
            "b",
            "lead",
            "a cycle of leads",
        ),
        (
            {
                "a": _team(lead="x", follow=["y"]),
                "b": _team(lead="y", follow=["z"]),
                "c": _team(lead="z", follow=["x"]),
            },
            "c",
            "lead",
            "a cycle of leads",
        ),
    ],
)
def test_teams_that_clash_refuse_the_later_one(
    teams: dict[str, m.TeamUpdate], team: str, path: str, reason: str
) -> None:
    problems = m.team_problems(teams, known={"m1", "r1", "x", "y", "z"})
    assert [p.team for p in problems] == [team]
    assert problems[0].error.path == path
    assert reason in problems[0].error.reason


def test_without_known_units_any_unit_may_be_named() -> None:
    assert m.team_problems({"a": _team(lead="r1", follow=["m9"])}) == []
