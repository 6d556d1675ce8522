"""A lead's route priced for its followers (issue 33): a gap the lead fits through and the corridor does not,
and ground the lead climbs and its follower cannot, are not chosen for the lead; its preview shows the same."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from pfp_service.core import PlannerParams
from pfp_service.core.zones import Zone, ZoneSet
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.live import of_grid
from pfp_service.wire import Goal, GoalMobility, UnitState
from pfp_service.wire.messages import TeamUpdate, ZoneUpdate
from pfp_service.world.team_route import widened
from pfp_service.world.world import GoalSet, StateReported, TeamPut, World, WorldSettings, ZonePut

pytestmark = pytest.mark.unit

CORRIDOR_M = 30.0
# two walls 10 m apart across the lead's straight way: a point passes, a 30 m corridor does not
WALLS = {
    "west": [[-300.0, 180.0], [-5.0, 180.0], [-5.0, 220.0], [-300.0, 220.0]],
    "east": [[5.0, 180.0], [300.0, 180.0], [300.0, 220.0], [5.0, 220.0]],
}


def _gap_world(team: bool) -> World:
    w = World(WorldSettings(planner=PlannerParams(intensity="density", step=2.0), deliberation="inline"))
    w.apply(
        [ZonePut(z, ZoneUpdate(polygon=[[*map(tuple, ring), tuple(ring[0])]])) for z, ring in WALLS.items()],
        0.0,
    )
    w.apply([StateReported("s1", UnitState(position=(0.0, 0.0))), StateReported("m1", UnitState(position=(0.0, -40.0)))], 0.0)  # fmt: skip
    if team:
        w.apply(
            [TeamPut("alpha", TeamUpdate(lead="s1", follow=["m1"], standoff_m=20.0, corridor_m=CORRIDOR_M))],
            0.0,
        )
    w.apply([GoalSet(u, Goal(position=(0.0, 400.0), tolerance=5.0)) for u in ("s1", "m1")], 0.0)
    return w


def _drive(w: World, seconds: float, dt: float = 0.5) -> dict[str, list[tuple[float, float]]]:
    """Both units driven along their directions at 3 m/s, no further than each holds, reporting every ``dt``."""
    at = {"s1": (0.0, 0.0), "m1": (0.0, -40.0)}
    tracks: dict[str, list[tuple[float, float]]] = {u: [p] for u, p in at.items()}
    out = w.apply([StateReported(u, UnitState(position=p, speed_mps=0.0)) for u, p in at.items()], 0.0)
    last = {d.unit: d for d in out.directions}
    t = 0.0
    while t < seconds and not all(d.status.value == "arrived" for d in last.values()):
        t += dt
        for u, p in at.items():
            d = last.get(u)
            run = 0.0 if d is None or not d.reach_m else min(3.0 * dt, d.reach_m)
            v = d.vector if d is not None else (0.0, 0.0)
            at[u] = (p[0] + v[0] * run, p[1] + v[1] * run)
            tracks[u].append(at[u])
        out = w.apply([StateReported(u, UnitState(position=p, speed_mps=3.0)) for u, p in at.items()], t)
        last.update({d.unit: d for d in out.directions})
    return tracks


def _walls() -> shapely.Geometry:
    return shapely.union_all([shapely.Polygon(r) for r in WALLS.values()])


def test_alone_the_units_take_the_gap_and_as_a_column_they_keep_the_corridor_clear() -> None:
    walls = _walls()
    alone = _drive(_gap_world(team=False), seconds=300.0)
    assert math.dist(alone["s1"][-1], (0.0, 400.0)) < 10.0  # through the 10 m gap
    assert min(walls.distance(shapely.Point(p)) for p in alone["s1"]) < CORRIDOR_M / 2
    # the same units as a team: s1 leads, m1 follows on the ground it cleared; the column's route is
    # priced for the corridor, so the lead never comes within half the corridor of a wall
    w = _gap_world(team=True)
    view = w.view("s1")  # what a preview plans over: the walls grown by the corridor's half
    assert view.zones is not None and view.zones.zone_at(0.0, 200.0) and view.zones.zone_at(-314.0, 200.0)
    led = _drive(w, seconds=600.0)
    assert min(walls.distance(shapely.Point(p)) for p in led["s1"]) >= CORRIDOR_M / 2 - 1e-6
    assert max(abs(p[0]) for p in led["s1"]) > 300.0  # it went round a wall's end
    assert math.dist(led["s1"][-1], (0.0, 400.0)) < 10.0 and led["m1"][-1][1] > 300.0  # and both got there


def test_a_grown_zone_contains_the_round_buffer_and_a_circle_grows_exactly() -> None:
    wall = Zone.polygon("w", [(0.0, 0.0), (10.0, 0.0), (10.0, 2.0), (0.0, 2.0)])
    grown = widened(wall, 5.0)
    assert grown.id == "w" and grown.geometry.covers(wall.geometry.buffer(5.0, quad_segs=64))
    assert widened(Zone.circle("c", (1.0, 2.0), 3.0), 5.0).radius_m == 8.0
    assert ZoneSet([grown]).zone_at(5.0, 6.5) == "w"


def _mesa() -> TerrainGrid:
    """A plateau 100 m high, 800 m in radius, with walls of 22 degrees: a soldier climbs them, a truck does not."""
    xs = np.linspace(-3000.0, 3000.0, 301)
    gx, gy = np.meshgrid(xs, xs)
    rise = (np.hypot(gx, gy) - 800.0) * math.tan(math.radians(22.0))
    return TerrainGrid(-3000.0, -3000.0, xs[1] - xs[0], np.clip(100.0 - rise, 0.0, 100.0))


def test_a_lead_on_foot_leading_a_truck_plans_round_the_slope_the_truck_cannot_climb() -> None:
    ground = of_grid(_mesa(), "foot")
    w = World(WorldSettings(planner=PlannerParams(), deliberation="inline", terrain=ground, lookahead=0))
    w.apply([StateReported("s1", UnitState(position=(0.0, -2000.0))), StateReported("m1", UnitState(position=(0.0, -2100.0)))], 0.0)  # fmt: skip
    foot = Goal(position=(0.0, 0.0), mobility=GoalMobility(kind="foot"))
    truck = Goal(position=(0.0, 0.0), tolerance=100.0, mobility=GoalMobility(kind="wheeled"))
    w.apply([GoalSet("m1", truck), GoalSet("s1", foot)], 0.0)
    assert not any(z.startswith("slope>") for z in w.view("s1").zones.ids)  # alone: the mesa is open to it
    w.apply([TeamPut("alpha", TeamUpdate(lead="s1", follow=["m1"], corridor_m=CORRIDOR_M))], 1.0)
    assert any(z.startswith("slope>17deg") for z in w.view("s1").zones.ids)  # leading the truck: its limit
