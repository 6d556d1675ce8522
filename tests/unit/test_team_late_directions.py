"""A follower whose directions come late still keeps to its lead's cleared corridor (``pfp demo --teams``'s team).

The fleet waits a while for each answer (lockstep), then moves on: under load a direction can come a
tick or more after the report it answers, or again for the same report when the world changed (a threat
put). The planner judged its ``reach_m`` from that report, so the vehicle drives the leg from there
(``SimUnit``), not ``reach_m`` afresh from where the direction found it. Judged by the inject
expectation's own check on the reported tracks (``team_expectations.only_cleared_by``).
"""

from __future__ import annotations

import math

import pytest
from pfp_clients.script import Expect
from pfp_clients.sim import SimUnit
from pfp_clients.team_expectations import only_cleared_by

from pfp_service.core import PlannerParams
from pfp_service.team import UnitSpec
from pfp_service.wire import Direction, Goal, ThreatUpdate, UnitKind
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.world import StateReported, TeamPut, ThreatPut, Tick, World, WorldSettings

pytestmark = pytest.mark.unit

DT = 0.2  # the fleet's tick: one report of its fastest unit (5 Hz)
TEAM = TeamUpdate(
    lead="r1",
    follow=["m1"],
    standoff_m=30.0,
    corridor_m=8.0,
    controller="m1",
    robots=["r1"],
    radio_range_m=80.0,
    spacing_m=12.0,
    goal=Goal(position=(200.0, 0.0), tolerance=1.5),
)
THREAT = ThreatUpdate(
    position=(100.0, -4.0), facing_deg=270.0, sigma_range=10.0, sigma_lateral=6.0, skew=2.0, weight=20.0
)


def _drive(late_ticks: int) -> tuple[dict[str, SimUnit], dict[str, list[tuple[float, float, float]]]]:
    """The team driven as the fleet drives it, each tick's directions handed over ``late_ticks`` ticks late."""
    w = World(WorldSettings(planner=PlannerParams(intensity="density")))
    w.apply([TeamPut("alpha", TEAM)], 0.0)
    fleet = {
        "r1": SimUnit(UnitSpec(id="r1", start=(10.0, 0.0), speed_mps=3.0), rate_hz=5.0),
        "m1": SimUnit(UnitSpec(id="m1", start=(0.0, 0.0), speed_mps=2.0, kind=UnitKind.MANNED), rate_hz=2.0),
    }
    tracks: dict[str, list[tuple[float, float, float]]] = {u: [] for u in fleet}
    pending: list[list[Direction]] = []
    popped, t = False, 0.0
    for _ in range(1500):
        inputs: list[object] = []
        for u in fleet.values():
            if u.due(t):
                s = u.state(t)
                inputs.append(StateReported(u.id, s))
                tracks[u.id].append((t, *s.position))
        if not popped and math.dist(fleet["m1"].position, (50.0, 0.0)) <= 5.0:  # in the scout's way
            inputs.append(ThreatPut("e1", THREAT))
            popped = True
        pending.append(list(w.apply([*inputs, Tick(t)], t).directions))  # type: ignore[list-item]
        if len(pending) > late_ticks:
            for d in pending.pop(0):
                fleet[d.unit].on_direction(d, t)
        t = round(t + DT, 9)
        for u in fleet.values():
            u.advance(DT, t, 0.0)
        if all(u.arrived for u in fleet.values()):
            break
    assert popped
    return fleet, tracks


@pytest.mark.parametrize("late_ticks", [0, 1, 2, 3, 5])
def test_a_follower_answered_late_never_leaves_the_ground_its_lead_cleared(late_ticks: int) -> None:
    fleet, tracks = _drive(late_ticks)
    assert fleet["m1"].arrived and fleet["r1"].arrived
    expect = Expect(unit="m1", only_cleared_by="r1", corridor_m=TEAM.corridor_m)
    held, detail = only_cleared_by(expect, tracks["m1"], tracks["r1"])
    assert held, detail
