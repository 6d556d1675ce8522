"""A controller between two robots over real terrain chooses a place that keeps both linked (issue 33),
rather than cutting its step short for one of them and being pulled by each in turn."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.live import LiveTerrain, of_grid
from pfp_service.wire import Direction, DirectionStatus, Goal
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world import team_place
from pfp_service.world import teams as roles
from pfp_service.world.team_book import TeamBook
from pfp_service.world.units import UnitRecord

pytestmark = pytest.mark.unit

Point = tuple[float, float]
CELL_M = 10.0
XS = np.arange(101) * CELL_M - 500.0
M1, R1, R2 = (0.0, 0.0), (-200.0, -200.0), (200.0, 200.0)  # the controller on the crest, a robot each side


def _crest() -> LiveTerrain:
    """Flat ground at 100 m and a ridge 40 m high whose crest runs north-west through the origin."""
    gx, gy = np.meshgrid(XS, XS)
    s = (gx + gy) / math.sqrt(2.0)  # across the ridge
    return of_grid(TerrainGrid(-500.0, -500.0, CELL_M, 100.0 + 40.0 * np.exp(-(s**2) / (2 * 30.0**2))))


def _direction(unit: str, vector: Point, reach_m: float) -> Direction:
    return Direction(unit=unit, vector=vector, status=DirectionStatus.EN_ROUTE, reach_m=reach_m)


def _judge(ground: LiveTerrain) -> Direction:
    """The controller's step west, judged by the team book with its robots held each side of the crest."""
    book = TeamBook(ground.sees)
    book.put("alpha", TeamUpdate(controller="m1", robots=["r1", "r2"], radio_range_m=1500.0))
    units = {
        u: UnitRecord(u, k, position=p, goal=Goal(position=(p[0] - 400.0, p[1])))
        for k, (u, p) in enumerate([("m1", M1), ("r1", R1), ("r2", R2)])
    }
    west, hold = _direction("m1", (-1.0, 0.0), 60.0), _direction("r1", (0.0, 0.0), 0.0)
    out = book.judge([west, hold, _direction("r2", (0.0, 0.0), 0.0)], units, now=0.0)
    return out[0]


def test_the_ground_hides_each_robot_from_the_far_flank() -> None:
    ground = _crest()
    assert ground.sees(M1, R1) and ground.sees(M1, R2)
    assert not ground.sees((-40.0, 0.0), R2) and not ground.sees((40.0, 0.0), R1)
    v, robot = roles.control(M1, (-40.0, 0.0), [("r1", R1), ("r2", R2)], 1500.0, ground.sees)
    assert v.kind == "to" and v.to is not None and v.to[0] > -12.0 and robot == "r2"  # cut: r2 hides


def test_a_controller_between_two_robots_steps_along_the_crest_that_keeps_both() -> None:
    ground = _crest()
    d = _judge(ground)
    assert d.reach_m is not None and d.reach_m > 0.0, d
    end = (d.vector[0] * d.reach_m, d.vector[1] * d.reach_m)
    assert ground.sees(end, R1) and ground.sees(end, R2), end  # the world's own test: both kept
    cut, _ = roles.control(M1, (-60.0, 0.0), [("r1", R1), ("r2", R2)], 1500.0, ground.sees)
    assert cut.to is not None  # nearer the end of its own step than the step cut for r2
    assert math.dist(end, (-60.0, 0.0)) < math.dist(cut.to, (-60.0, 0.0)) - 5.0, (end, cut)
    assert end[0] < cut.to[0] - 2.0, (end, cut)  # and further west
    assert "to a place that keeps r1, r2 linked" in d.reason, d.reason
    f = np.linspace(0.0, 1.0, 21)  # and on the way there
    assert all(ground.sees((end[0] * k, end[1] * k), r) for k in f.tolist() for r in (R1, R2))


def test_a_step_that_keeps_every_robot_stands() -> None:
    ground = _crest()
    robots = [("r1", R1), ("r2", R2)]
    along = (-20.0, 20.0)  # along the crest: both stay in sight
    v, _ = roles.control(M1, along, robots, 1500.0, ground.sees)
    assert v == roles.GO
    assert team_place.place(M1, along, v, robots, 1500.0, ground.sees) is None
    assert team_place.control(M1, along, robots, 1500.0, ground.sees) == (roles.GO, "")


def test_a_controller_of_one_robot_is_judged_as_before() -> None:
    ground = _crest()
    robots = [("r2", R2)]
    assert team_place.control(M1, (-40.0, 0.0), robots, 1500.0, ground.sees) == roles.control(
        M1, (-40.0, 0.0), robots, 1500.0, ground.sees
    )


def test_a_follower_controller_keeps_to_its_cleared_ground() -> None:
    """The crest is off the corridor its lead cleared (due west): no place there, so the cut stands."""
    ground = _crest()
    robots = [("r1", R1), ("r2", R2)]
    track = roles.Polyline([(60.0, 0.0), (-300.0, 0.0)])
    cut = roles.control(M1, (-40.0, 0.0), robots, 1500.0, ground.sees)
    got = team_place.control(M1, (-40.0, 0.0), robots, 1500.0, ground.sees, ground=(track, 10.0))
    assert got == cut


def test_a_controller_closing_on_one_robot_goes_round_by_the_crest_that_keeps_the_other() -> None:
    """Closing on r1 (its link holds it) down the far flank would lose r2: the crest keeps both and is nearer r1."""
    ground = _crest()
    r1 = (-300.0, -100.0)  # west-south-west, below the crest
    others = [("r2", R2)]
    cut, robot = roles.control(M1, r1, others, 1500.0, ground.sees, None, 15.0)  # a report's run: 15 m
    assert cut.kind == "to" and cut.to is not None and robot == "r2"
    v, robot = team_place.control(M1, r1, others, 1500.0, ground.sees, None, 15.0, closing=("r1", r1))
    assert v.kind == "to" and v.to is not None and robot == "", v
    assert math.dist(M1, v.to) <= 15.0 + 1e-9
    assert ground.sees(v.to, r1) and ground.sees(v.to, R2), v
    assert math.dist(v.to, r1) < math.dist(cut.to, r1) - 3.0, (v, cut)  # nearer r1 than the cut step
    assert v.reason == "the step would break r2's link; to a place that keeps r2, r1 linked"
