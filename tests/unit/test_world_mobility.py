"""A unit's mobility class on its goal: its own slope barriers over terrain (issue 32).

The ground is a mesa whose walls climb 22 degrees: steeper than a wheeled
vehicle's 17, gentler than a soldier's 30.  The same goal on a wall is
crossable on foot and a barrier to a wheeled vehicle, whose goal is then
``trapped`` with a reason naming the slope.
"""

from __future__ import annotations

import json
import math

import msgspec
import numpy as np
import pytest

from pfp_service.core import PlannerParams
from pfp_service.errors import InputError
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.live import BARRIER_SETS, of_grid
from pfp_service.wire import Goal, GoalMobility, RejectedEvent, TrappedEvent, UnitState
from pfp_service.world.kinds import KINDS
from pfp_service.world.world import GoalSet, StateReported, World, WorldSettings

pytestmark = pytest.mark.unit

WALL_DEG = 22.0
ON_THE_WALL = (0.0, -920.0)  # halfway up the mesa's south wall


def _mesa(side: int = 301) -> TerrainGrid:
    xs = np.linspace(-3000.0, 3000.0, side)
    gx, gy = np.meshgrid(xs, xs)
    rise = (np.hypot(gx, gy) - 800.0) * math.tan(math.radians(WALL_DEG))
    return TerrainGrid(-3000.0, -3000.0, xs[1] - xs[0], np.clip(100.0 - rise, 0.0, 100.0))


def _world() -> World:
    ground = of_grid(_mesa(), "foot")  # the planner's class: a unit whose goal names none plans as foot
    return World(WorldSettings(planner=PlannerParams(), deliberation="inline", terrain=ground, lookahead=0))


def _goal(kind: str | None, max_slope_deg: float | None = None) -> Goal:
    mob = None if kind is None else GoalMobility(kind=kind, max_slope_deg=max_slope_deg)
    return Goal(position=ON_THE_WALL, mobility=mob)


def _send(w: World, goals: dict[str, Goal]):
    starts = {uid: (-60.0 + 40.0 * k, -2000.0) for k, uid in enumerate(goals)}
    w.apply([StateReported(uid, UnitState(position=xy, seq=1)) for uid, xy in starts.items()], 0.0)
    return w.apply([GoalSet(uid, goal) for uid, goal in goals.items()], 0.0)


def test_the_same_goal_on_a_slope_is_reached_on_foot_and_trapped_on_wheels_naming_the_slope():
    w = _world()
    out = _send(
        w,
        {
            "foot": _goal("foot"),
            "wheels": _goal("wheeled"),
            "planner_class": _goal(None),
            "climber": _goal("wheeled", max_slope_deg=30.4),  # an override, planned at foot's 30 degrees
            "careful": _goal("foot", max_slope_deg=25.0),  # planned at wheels' 17: the safe side
        },
    )
    status = {d.unit: d for d in out.directions}
    assert status["foot"].status.value == "en_route", status["foot"]
    assert status["planner_class"].status.value == "en_route"
    assert status["climber"].status.value == "en_route"
    for uid in ("wheels", "careful"):
        assert status[uid].status.value == "trapped", status[uid]
        assert "slope>17deg" in (status[uid].reason or "")
    trapped = {e.unit: e for e in out.events if isinstance(e, TrappedEvent)}
    assert set(trapped) == {"wheels", "careful"} and "slope>17deg" in trapped["wheels"].reason
    # the preview of each unit plans round its own barriers
    wheels, foot = w.view("wheels").zones.ids, w.view("foot").zones.ids
    assert any(z.startswith("slope>17deg") for z in wheels)
    assert not any(z.startswith("slope>") for z in foot)  # no ground of this mesa is past 30 degrees


def test_a_goal_without_terrain_ignores_its_class():
    w = World(WorldSettings(planner=PlannerParams(), deliberation="inline", lookahead=0))
    out = _send(w, {"a": _goal("wheeled")})
    assert [d.status.value for d in out.directions] == ["en_route"]


def test_an_unknown_class_is_refused_naming_its_field_and_the_other_units_carry_on():
    w = _world()
    out = _send(w, {"bad": _goal("hovercraft"), "good": _goal("foot")})
    (rejected,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert rejected.key.endswith("/unit/bad/goal") and rejected.field == "$.mobility.class"
    assert "hovercraft" in rejected.reason
    assert {d.unit: d.status.value for d in out.directions}["good"] == "en_route"
    # from the wire: the goal's decoder refuses it before it is stored
    (goal_kind,) = [k for k in KINDS if k.name == "goal"]
    body = {"position": [0, 0], "mobility": {"class": "hovercraft"}}
    with pytest.raises(InputError) as err:
        goal_kind.decode(json.dumps(body).encode(), None, None)
    assert err.value.path == "$.mobility.class"
    ok = goal_kind.decode(json.dumps({**body, "mobility": {"class": "tracked"}}).encode(), None, None)
    assert ok.mobility == GoalMobility(kind="tracked")
    too_gentle = {"class": "foot", "max_slope_deg": 10}  # below every class's limit: no barriers held for it
    for bad in (
        {"class": "foot", "max_slope_deg": 90},
        {"class": "Foot!"},
        {"max_slope_deg": 20},
        too_gentle,
    ):
        with pytest.raises(InputError) as err:
            goal_kind.decode(json.dumps({**body, "mobility": bad}).encode(), None, None)
        assert err.value.path.startswith("$.mobility")


def test_barrier_sets_are_made_when_first_asked_and_bounded():
    ground = of_grid(_mesa(101), "foot")
    assert ground.barriers(None) is ground.zones
    first = ground.barriers(17)
    assert first and ground.barriers(17) is first  # cached
    for deg in range(1, BARRIER_SETS + 3):
        ground.barriers(deg)
    assert len(ground._sets) == BARRIER_SETS


def _drive(w: World, uid: str, start: tuple[float, float], goal: Goal, steps: int = 400):
    """Drive ``uid`` along its directions until it arrives or is trapped: its last direction and its track."""
    x, y = start
    w.apply([StateReported(uid, UnitState(position=(x, y), seq=0))], 0.0)
    out = w.apply([GoalSet(uid, goal)], 0.0)
    track = [(x, y)]
    for k in range(1, steps):
        (d,) = [d for d in out.directions if d.unit == uid]
        if d.status.value in ("arrived", "trapped"):
            return d, track
        hop = min(d.reach_m or 25.0, 25.0)
        x, y = x + hop * d.vector[0], y + hop * d.vector[1]
        track.append((x, y))
        out = w.apply([StateReported(uid, UnitState(position=(x, y), seq=k))], float(k))
    return d, track


def test_a_mesa_top_is_climbed_on_foot_and_its_walls_trap_a_wheeled_unit_after_deliberating():
    top = Goal(position=(0.0, 0.0), tolerance=20.0)
    foot, walked = _drive(
        _world(), "foot", (0.0, -2000.0), msgspec.structs.replace(top, mobility=GoalMobility(kind="foot"))
    )
    wheels, driven = _drive(
        _world(),
        "wheels",
        (0.0, -2000.0),
        msgspec.structs.replace(top, mobility=GoalMobility(kind="wheeled")),
    )
    assert foot.status.value == "arrived", foot
    assert math.hypot(*walked[-1]) < 100.0  # up the wall, onto the top
    assert wheels.status.value == "trapped" and "slope>17deg" in (wheels.reason or ""), wheels
    assert math.hypot(*driven[-1]) > 800.0  # it never climbed the wall
