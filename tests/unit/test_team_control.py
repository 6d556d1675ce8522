"""A controller's own step keeps its robots' links (issue 33): it is cut short where a robot it is linked to
would fall out of range or sight, and a robot its controller holds for closes on it, so neither waits for the
other for ever."""

from __future__ import annotations

import math

import pytest

from pfp_service.core import PlannerParams
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world import teams as roles
from pfp_service.world.world import TeamPut, World, WorldSettings
from tests.unit.test_teams_roles import _ridge_sight
from tests.unit.test_world_teams import _drive

pytestmark = pytest.mark.unit


def test_a_controllers_step_stops_short_of_a_robots_range_and_shadow() -> None:
    v, robot = roles.control((0.0, 0.0), (-80.0, 0.0), [("r1", (250.0, 0.0))], 300.0)
    assert v.kind == "to" and v.to is not None and -50.0 <= v.to[0] < -30.0 and robot == "r1"
    assert v.reason == "the step would break r1's link"
    v, robot = roles.control((-50.0, 0.0), (-60.0, 0.0), [("r1", (250.0, 0.0))], 300.0)
    assert v.kind == "hold" and robot == "r1"
    # a robot already out of the link turns back on its own: it holds nobody
    assert roles.control((0.0, 0.0), (-80.0, 0.0), [("r1", (400.0, 0.0))], 300.0) == (roles.GO, "")
    sight = _ridge_sight()  # seen from the controller's cell (10, 0): not past the ridge at x = 50
    assert roles.control((10.0, 0.0), (10.0, 0.0), [("r1", (45.0, 0.0))], 500.0, sight)[0] == roles.GO


def test_a_controller_walking_away_keeps_its_robot_and_the_robot_closes_on_it() -> None:
    w = World(WorldSettings(planner=PlannerParams(intensity="density", step=0.5)))
    w.apply([TeamPut("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=100.0))], 0.0)
    tracks, said = _drive(
        w,
        start={"m1": (0.0, 0.0), "r1": (60.0, 0.0)},
        goal={"m1": (-300.0, 0.0), "r1": (300.0, 0.0)},  # opposite ways
        speed={"m1": 2.0, "r1": 2.0},
        seconds=120.0,
    )
    apart = [math.dist(a, b) for a, b in zip(tracks["m1"], tracks["r1"])]
    assert max(apart) <= 100.0 + 1e-6, max(apart)
    reasons = {d.reason for d in said}
    assert "team alpha: the step would break r1's link" in reasons
    assert "team alpha: closing on m1, which holds for its link" in reasons
    assert tracks["m1"][-1][0] < -60.0  # the pair got on: the controller's way, the robot in tow


def test_a_robot_closing_on_its_controller_keeps_out_of_a_keep_out_zone_between_them() -> None:
    """A role's step goes straight to its point: it is cut short of a zone on the way, as the planner's are."""
    from shapely.geometry import LineString, box

    from pfp_service.wire.messages import ZoneUpdate
    from pfp_service.world.world import ZonePut

    w = World(WorldSettings(planner=PlannerParams(intensity="density", step=0.5)))
    ring = [(20.0, -10.0), (40.0, -10.0), (40.0, 10.0), (20.0, 10.0), (20.0, -10.0)]
    w.apply([ZonePut("pit", ZoneUpdate(polygon=[ring]))], 0.0)
    w.apply([TeamPut("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=100.0))], 0.0)
    tracks, said = _drive(
        w,
        start={"m1": (0.0, 0.0), "r1": (60.0, 0.0)},
        goal={"m1": (-300.0, 0.0), "r1": (300.0, 0.0)},
        speed={"m1": 2.0, "r1": 2.0},
        seconds=60.0,
    )
    told = {d.reason for d in said if d.unit == "r1"}
    assert any("closing on m1" in r or "turning back" in r for r in told), told  # the roles pulled it west
    pit = box(20.0, -10.0, 40.0, 10.0)
    assert not LineString(tracks["r1"]).intersects(pit), "the robot drove into the keep-out zone"
