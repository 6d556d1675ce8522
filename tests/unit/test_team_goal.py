"""A team goal: one goal for the team, each member given its place (a column on the cleared corridor, or a
formation's offsets), and the team's ETA, its slowest member's, in its state and in ``pfp status``."""

from __future__ import annotations

import math

import msgspec
import pytest
import shapely

from pfp_service.core import PlannerParams
from pfp_service.errors import InputError
from pfp_service.wire import DirectionStatus, Goal, ThreatUpdate, decode_world_snapshot, encode
from pfp_service.wire.messages import TeamUpdate, decode_team
from pfp_service.world import team_goal
from pfp_service.world.world import StateReported, TeamPut, ThreatPut, World, WorldSettings
from tests.unit.test_world_teams import _drive, _report

pytestmark = pytest.mark.unit

GOAL = Goal(position=(240.0, 0.0), tolerance=1.0)
SCOUTED = TeamUpdate(
    lead="r1",
    follow=["m1", "m2"],
    standoff_m=30.0,
    corridor_m=6.0,
    controller="m1",
    robots=["r1"],
    radio_range_m=80.0,
    spacing_m=8.0,
    goal=GOAL,
)


def _world() -> World:
    return World(WorldSettings(planner=PlannerParams(intensity="density", step=0.5)))


def test_places_put_the_column_in_order_and_a_formation_at_its_offsets() -> None:
    got = team_goal.places(SCOUTED)
    assert list(got) == ["r1", "m1", "m2"]
    assert {g.position for g in got.values()} == {(240.0, 0.0)}
    assert [g.tolerance for g in got.values()] == [1.0, 9.0, 17.0]
    wedge = TeamUpdate(members=["a", "b", "c"], goal=GOAL, offsets={"b": (-20.0, -20.0), "c": (20.0, -20.0)})
    got = team_goal.places(wedge)
    assert got["a"] == GOAL and got["b"].position == (220.0, -20.0) and got["c"].position == (260.0, -20.0)
    # without spacing_m the column keeps the team's separation, else the default
    assert (
        team_goal.places(TeamUpdate(members=["a", "b"], goal=Goal(position=(0.0, 0.0))))["b"].tolerance
        == 50.0
    )
    sep = TeamUpdate(members=["a", "b"], separation_m=15.0, goal=Goal(position=(0.0, 0.0)))
    assert team_goal.places(sep)["b"].tolerance == 15.0
    assert team_goal.places(TeamUpdate(members=["a"])) == {}


def test_a_bad_team_goal_is_refused_with_its_field() -> None:
    with pytest.raises(InputError) as e:
        decode_team(b'{"members": ["a"], "offsets": {"a": [1, 2]}}')
    assert e.value.path == "$.offsets"
    with pytest.raises(InputError) as e:
        decode_team(b'{"members": ["a"], "goal": {"position": [0, 0]}, "offsets": {"x": [1, 2]}}')
    assert e.value.path == "$.offsets.x" or "offsets.x" in e.value.reason
    bounds = ((-100.0, -100.0), (100.0, 100.0))
    with pytest.raises(InputError) as e:
        decode_team(b'{"members": ["a"], "goal": {"position": [0, 0]}, "offsets": {"a": [150, 0]}}', bounds)
    assert e.value.path == "$.offsets.a"
    with pytest.raises(InputError) as e:
        decode_team(b'{"members": ["a"], "goal": {"position": [500, 0]}}', bounds)
    assert e.value.path == "$.goal.position"


def test_a_team_goal_sets_each_members_goal_once_and_a_put_again_keeps_their_missions() -> None:
    w = _world()
    w.apply([_report(u, (float(i), 0.0), 0.0) for i, u in enumerate(["m2", "m1", "r1"])], 0.0)
    out = w.apply([TeamPut("alpha", SCOUTED)], 1.0)
    assert {d.unit for d in out.directions} == {"m1", "m2", "r1"}
    goals = {u: w._units[u].goal for u in ("r1", "m1", "m2")}
    assert goals == team_goal.places(SCOUTED)
    epochs = {u: w._units[u].epoch for u in goals}
    w.apply([TeamPut("alpha", msgspec.structs.replace(SCOUTED, standoff_m=35.0))], 2.0)  # the same places
    assert {u: w._units[u].epoch for u in goals} == epochs
    moved = msgspec.structs.replace(SCOUTED, goal=Goal(position=(200.0, 10.0), tolerance=1.0))
    w.apply([TeamPut("alpha", moved)], 3.0)
    assert w._units["m2"].goal == Goal(position=(200.0, 10.0), tolerance=17.0)


def test_a_column_arrives_in_order_on_the_cleared_corridor_with_a_threat_mid_route() -> None:
    """The product question "a follower whose goal is outside its lead's corridor": a column place cannot be."""
    w = _world()
    w.apply(
        [_report(u, p, 0.0) for u, p in {"r1": (6.0, 0.0), "m1": (0.0, 0.0), "m2": (-8.0, 0.0)}.items()], 0.0
    )
    w.apply([TeamPut("alpha", SCOUTED)], 0.0)
    bad = ThreatUpdate(
        position=(120.0, -3.0), facing_deg=270.0, sigma_range=10.0, sigma_lateral=6.0, skew=2.0, weight=20.0
    )
    tracks, said = _drive(
        w,
        start={"r1": (6.0, 0.0), "m1": (0.0, 0.0), "m2": (-8.0, 0.0)},
        goal={},
        speed={"r1": 3.0, "m1": 2.0, "m2": 2.0},
        seconds=260.0,
        events=[(40.0, ThreatPut("t1", bad))],
    )
    ends = {u: tr[-1] for u, tr in tracks.items()}
    assert math.dist(ends["r1"], (240.0, 0.0)) <= 1.0 + 0.5, ends
    assert 0.5 <= 240.0 - ends["m1"][0] <= 9.0 + 1.0 and 8.5 <= 240.0 - ends["m2"][0] <= 17.0 + 1.0, ends
    assert all(w._units[u].last_status is DirectionStatus.ARRIVED for u in ("r1", "m1", "m2"))
    cleared = shapely.LineString(tracks["r1"]).buffer(3.0 + 0.05)
    for u in ("m1", "m2"):  # each place on the corridor: the follower arrived inside it, never held outside
        assert cleared.contains(shapely.Point(ends[u])), (u, ends[u])
    assert not any("end of the ground" in d.reason for d in said[-6:])
    (t,) = decode_world_snapshot(encode(w.snapshot(260.0))).teams
    assert t.eta_s == 0.0 and t.slowest in {"r1", "m1", "m2"}


def test_the_team_eta_is_its_slowest_members_and_status_shows_it() -> None:
    from pfp_service.cli.status import snapshot_lines

    w = _world()
    team = TeamUpdate(members=["a", "b"], goal=Goal(position=(100.0, 0.0), tolerance=1.0), spacing_m=10.0)
    w.apply([TeamPut("alpha", team)], 0.0)
    w.apply([_report("a", (0.0, 0.0), 2.0), _report("b", (50.0, 0.0), 1.0)], 1.0)
    (t,) = w.snapshot(1.0).teams
    # a: 100 m less its 1 m circle at 2 m/s; b: 50 m less its 11 m circle at 1 m/s
    assert t.slowest == "a" and t.eta_s == pytest.approx(49.5)
    text = "\n".join(snapshot_lines(decode_world_snapshot(encode(w.snapshot(1.0)))))
    assert "ETA 50 s (a)" in text, text
    w.apply([StateReported("b", msgspec.structs.replace(_report("b", (50.0, 0.0), 0.0).state))], 2.0)
    (t,) = w.snapshot(2.0).teams
    assert t.eta_s is None and t.slowest == "b"
    assert "ETA unknown (b not moving)" in "\n".join(
        snapshot_lines(decode_world_snapshot(encode(w.snapshot(2.0))))
    )


def test_a_follower_whose_goal_lies_off_the_cleared_ground_holds_at_its_end_and_says_so() -> None:
    """Without a team goal the product question stands: the follower never enters uncleared ground, so it
    holds at the end of what its lead cleared, and its status names the goal that lies off it."""
    w = _world()
    w.apply([TeamPut("alpha", TeamUpdate(lead="r1", follow=["m1"], standoff_m=60.0, corridor_m=6.0))], 0.0)
    tracks, said = _drive(
        w,
        start={"r1": (6.0, 0.0), "m1": (0.0, 0.0)},
        goal={"r1": (120.0, 0.0), "m1": (60.0, 80.0)},
        speed={"r1": 3.0, "m1": 2.0},
        seconds=160.0,
    )
    (last,) = [d for d in said if d.unit == "m1"][-1:]
    assert (
        last.vector == (0.0, 0.0) and "at the cleared ground nearest its goal: its goal lies" in last.reason
    )
    cleared = shapely.LineString(tracks["r1"]).buffer(3.0 + 0.05)
    first = next(i for i, p in enumerate(tracks["m1"]) if cleared.contains(shapely.Point(p)))
    assert all(cleared.contains(shapely.Point(p)) for p in tracks["m1"][first:])
    assert math.dist(tracks["m1"][-1], (60.0, 80.0)) > 10.0
