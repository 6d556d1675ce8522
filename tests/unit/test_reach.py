"""A direction says how far its step goes (``reach_m``), and a vehicle that keeps to it never enters a zone.

The planner cuts a step short of a keep-out zone; the vector alone cannot say so.  A
simulated vehicle fast enough to cover ten steps between two directions is driven
against a wall across its way: it must go round, never through.
"""

from __future__ import annotations

import math

import pytest
from pfp_clients.sim import SimUnit
from shapely.geometry import LineString, Point, Polygon

from pfp_service.core import PlannerParams
from pfp_service.team import UnitSpec
from pfp_service.wire import Direction, DirectionStatus, Goal, UnitState
from pfp_service.wire.messages import ZoneUpdate
from pfp_service.world.world import GoalSet, StateReported, Tick, World, WorldSettings, ZonePut

pytestmark = pytest.mark.unit

RING = [(40.0, -30.0), (45.0, -30.0), (45.0, 30.0), (40.0, 30.0), (40.0, -30.0)]


def test_a_vehicle_keeping_to_reach_never_enters_a_zone_even_at_ten_steps_a_tick():
    params = PlannerParams(intensity="density")
    w = World(WorldSettings(planner=params))
    wall = Polygon(RING)
    w.apply([ZonePut("wall", ZoneUpdate(polygon=[RING]))], 0.0)
    w.apply([StateReported("u", UnitState(position=(0.0, 1.0)))], 0.0)
    w.apply([GoalSet("u", Goal(position=(100.0, 1.0)))], 0.0)
    unit = SimUnit(UnitSpec(id="u", start=(0.0, 1.0), speed_mps=1e6), position=(0.0, 1.0))
    reaches: list[float] = []
    t = 0.0
    for seq in range(1, 3000):
        t += 1.0
        out = w.apply([StateReported("u", UnitState(position=unit.position, seq=seq)), Tick(t)], t)
        mine = [d for d in out.directions if d.unit == "u" and d.seq == seq]
        if not mine:
            continue
        d = mine[-1]
        unit.on_direction(d, t)
        if d.status.value in ("arrived", "trapped"):
            break
        assert d.reach_m is not None and math.isfinite(d.reach_m)
        reaches.append(d.reach_m)
        unit.advance(1.0, t, t)
        assert not wall.contains(Point(unit.position)), f"entered the zone at {unit.position}"
    assert unit.direction is not None and unit.direction.status.value == "arrived"


def test_the_reach_of_every_direction_near_a_wall_stays_out_of_it():
    w = World(WorldSettings(planner=PlannerParams(intensity="density", step=5.0)))
    w.apply([ZonePut("wall", ZoneUpdate(polygon=[RING]))], 0.0)
    starts = {f"u{i}": (38.0 - 0.5 * (i % 8), -40.0 + 10.0 * (i // 8)) for i in range(72)}
    w.apply([StateReported(u, UnitState(position=p)) for u, p in starts.items()], 0.0)
    out = w.apply([GoalSet(u, Goal(position=(100.0, p[1]))) for u, p in starts.items()], 0.0)
    assert len(out.directions) == len(starts)
    for d in out.directions:
        x0, y0 = starts[d.unit]
        assert d.reach_m is not None and d.reach_m >= 0.0  # past the step on a route, never into the wall
        end = (x0 + d.vector[0] * d.reach_m, y0 + d.vector[1] * d.reach_m)
        assert not Polygon(RING).intersects(LineString([(x0, y0), end])), (d.unit, d.reach_m, d.vector)


def _direction(seq: int, vector: tuple[float, float], reach_m: float) -> Direction:
    return Direction(unit="u", seq=seq, status=DirectionStatus.EN_ROUTE, vector=vector, reach_m=reach_m)


def test_a_direction_sent_again_after_the_vehicle_moved_is_a_leg_from_where_it_reported():
    """The planner judged ``reach_m`` from the report: a second direction for the same report (a threat
    put meanwhile) ends where the planner said, not ``reach_m`` past where the vehicle had got to."""
    unit = SimUnit(UnitSpec(id="u", start=(0.0, 0.0), speed_mps=2.0))
    s = unit.state(0.0)
    unit.on_direction(_direction(s.seq, (1.0, 0.0), 3.0), 0.0)
    unit.advance(0.5, 0.5, 0.5)  # 1 m east, then the same report answered again: north-east, 2 m
    assert unit.position == pytest.approx((1.0, 0.0))
    v = (math.sqrt(0.5), math.sqrt(0.5))
    unit.on_direction(_direction(s.seq, v, 2.0), 0.5)
    for i in range(10):
        unit.advance(0.5, 1.0 + 0.5 * i, 0.0)
    end = (2.0 * v[0], 2.0 * v[1])  # the leg's end: 2 m from the report, not from (1, 0)
    assert math.dist(unit.position, end) < 1e-9, unit.position
    assert all(math.dist((p.x, p.y), (0.0, 0.0)) <= 2.0 + 1e-9 for p in unit.track[2:])


def test_a_leg_whose_end_the_vehicle_has_passed_holds_it_there_and_an_unknown_report_counts_from_receipt():
    unit = SimUnit(UnitSpec(id="u", start=(0.0, 0.0), speed_mps=2.0))
    s = unit.state(0.0)
    unit.on_direction(_direction(s.seq, (1.0, 0.0), 10.0), 0.0)
    unit.advance(1.0, 1.0, 1.0)  # 2 m east; the report answered again with a leg of 1 m: passed, it stops
    unit.on_direction(_direction(s.seq, (1.0, 0.0), 1.0), 1.0)
    unit.advance(1.0, 2.0, 2.0)
    assert unit.position == pytest.approx((2.0, 0.0))
    unit.on_direction(_direction(s.seq + 5, (0.0, 1.0), 1.5), 2.0)  # a report it never made: from here
    unit.advance(1.0, 3.0, 3.0)
    assert unit.position == pytest.approx((2.0, 1.5))
