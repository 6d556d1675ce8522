"""Team previews: a team replayed from its members' live states matches what the live world then drives.

The live side is the fleet's own simulated vehicles (``pfp_clients.sim.SimUnit``) driven by a live
``World``; the preview is ``team_preview.replay`` from ``team_preview.seed`` of that world mid-route.
"""

from __future__ import annotations

import math
import time

import pytest
from pfp_clients.sim import SimUnit

from pfp_service.core import PlannerParams
from pfp_service.errors import InputError
from pfp_service.team import UnitSpec
from pfp_service.wire import DirectionStatus, Goal, ThreatUpdate, UnitKind, UnitState
from pfp_service.wire.messages import TeamPreviewRequest, TeamUpdate
from pfp_service.world import team_preview
from pfp_service.world.world import GoalSet, StateReported, TeamPut, ThreatPut, World, WorldSettings

pytestmark = pytest.mark.unit

TEAM = TeamUpdate(
    lead="r1",
    follow=["m1"],
    standoff_m=30.0,
    corridor_m=6.0,
    controller="m1",
    robots=["r1"],
    radio_range_m=60.0,
)
DT = 0.5


def _fleet() -> dict[str, SimUnit]:
    specs = [
        UnitSpec(id="r1", start=(6.0, 0.0), goal=(260.0, 0.0), speed_mps=3.0),
        UnitSpec(id="m1", start=(0.0, 0.0), goal=(240.0, 0.0), speed_mps=2.0, kind=UnitKind.MANNED),
    ]
    return {s.id: SimUnit(s, rate_hz=1.0 / DT) for s in specs}


def _live(
    w: World, fleet: dict[str, SimUnit], t0: float, t1: float
) -> dict[str, list[tuple[float, float, float]]]:
    """The fleet driven by ``w`` from ``t0`` (its first move's end) to ``t1``: each unit's ``(t, x, y)`` as it reports."""
    tracks: dict[str, list[tuple[float, float, float]]] = {u: [] for u in fleet}
    t = t0
    while t <= t1 + 1e-9:
        for u in fleet.values():
            u.advance(DT, t, 0.0)
        out = w.apply([StateReported(u.id, u.state(t)) for u in fleet.values()], t)
        for d in out.directions:
            fleet[d.unit].on_direction(d, t)
        for u in fleet.values():
            tracks[u.id].append((t, *u.position))
        t = round(t + DT, 9)
    return tracks


def _world() -> World:
    w = World(WorldSettings(planner=PlannerParams(intensity="density", step=0.5)))
    bad = ThreatUpdate(
        position=(115.0, -3.0), facing_deg=270.0, sigma_range=10.0, sigma_lateral=6.0, skew=2.0, weight=20.0
    )
    w.apply([TeamPut("alpha", TEAM), ThreatPut("t1", bad)], 0.0)
    return w


def _start(w: World, fleet: dict[str, SimUnit]) -> None:
    w.apply([StateReported(u.id, u.state(0.0)) for u in fleet.values()], 0.0)
    out = w.apply([GoalSet(u.id, Goal(position=u.spec.goal, tolerance=1.0)) for u in fleet.values()], 0.0)  # type: ignore[arg-type]
    for d in out.directions:
        fleet[d.unit].on_direction(d, 0.0)


@pytest.mark.parametrize("at_s", [0.0, 30.0])
def test_a_team_preview_is_the_track_the_live_world_then_drives(at_s: float) -> None:
    w, fleet = _world(), _fleet()
    _start(w, fleet)
    if at_s:
        _live(w, fleet, DT, at_s)
    seeded = team_preview.seed(w, "alpha", at_s)
    assert seeded is not None and [m.unit for m in seeded.members] == ["m1", "r1"]
    speeds = {"r1": 3.0, "m1": 2.0}  # at the start no member has reported moving yet
    request = TeamPreviewRequest(horizon_s=300.0, dt_s=DT, speeds=speeds)
    got = team_preview.replay(seeded, request, time.monotonic, 60.0)
    live = _live(w, fleet, round(at_s + DT, 9), at_s + 300.0)
    assert got.stopped == "arrived" and got.eta_s is not None
    for m in got.members:
        by_t = {round(t - at_s, 6): (x, y) for t, x, y in live[m.unit]}
        gaps = [math.dist((x, y), by_t[round(t, 6)]) for t, x, y in m.points if round(t, 6) in by_t]
        assert len(gaps) >= len(m.points) - 1  # every replayed time but the first (now) is a live one
        assert max(gaps) <= 0.01, (m.unit, max(gaps))  # the same code on the same inputs: the same track
    # the team's ETA is its slowest member's, and the live fleet arrived then too
    arrived = {m.unit: m.arrived_s for m in got.members}
    assert got.eta_s == max(a for a in arrived.values() if a is not None)
    assert fleet["m1"].arrived and fleet["r1"].arrived
    m1 = next(m for m in got.members if m.unit == "m1")
    r1 = next(m for m in got.members if m.unit == "r1")
    assert any(s.reason.startswith("team alpha") for s in m1.statuses + r1.statuses)  # the roles' say
    assert m1.statuses[-1].status is DirectionStatus.ARRIVED


def test_a_team_preview_is_bounded_by_its_budget_and_refuses_a_member_without_speed() -> None:
    w, fleet = _world(), _fleet()
    _start(w, fleet)
    seeded = team_preview.seed(w, "alpha", 0.0)
    assert seeded is not None
    ticks = iter(range(10**6))
    request = TeamPreviewRequest(horizon_s=600.0, speeds={"m1": 2.0, "r1": 3.0})
    got = team_preview.replay(seeded, request, lambda: float(next(ticks)), 5.0)
    assert got.stopped == "budget" and got.eta_s is None and got.simulated_s < 10.0
    stopped = list(seeded.members)
    frozen = team_preview.TeamSeed(
        seeded.team_id,
        seeded.team,
        tuple(
            team_preview.MemberSeed(m.unit, m.position, 0.0, m.kind, m.goal, m.origin, m.stepper)
            for m in stopped
        ),
        seeded.track,
        seeded.held,
        seeded.settings,
        seeded.threats,
        seeded.zones,
    )
    with pytest.raises(InputError) as err:
        team_preview.replay(frozen, None, time.monotonic, 5.0)
    assert err.value.path == "$.speeds"
    given = TeamPreviewRequest(horizon_s=5.0, speeds={"m1": 2.0, "r1": 3.0})
    assert team_preview.replay(frozen, given, time.monotonic, 5.0).stopped == "horizon"
    assert team_preview.seed(w, "nobody", 0.0) is None


def test_a_team_preview_of_members_already_on_their_places_is_their_arrival() -> None:
    """Members the live world judged arrived are replayed as arrived (not restarted: a defect once)."""
    w = World(WorldSettings(planner=PlannerParams(), deliberation="inline", lookahead=0))
    w.apply(
        [
            StateReported(u, UnitState(position=p, seq=1, speed_mps=1.0))
            for u, p in (("a", (0.0, 0.0)), ("b", (100.0, 0.0)))
        ],
        0.0,
    )
    team = TeamUpdate(
        members=["a", "b"], goal=Goal(position=(100.0, 0.0), tolerance=1.0), offsets={"a": (-100.0, 0.0)}
    )
    out = w.apply([TeamPut("t", team)], 0.0)
    assert {(d.unit, d.status) for d in out.directions} == {
        ("a", DirectionStatus.ARRIVED),
        ("b", DirectionStatus.ARRIVED),
    }
    seeded = team_preview.seed(w, "t", 0.0)
    assert seeded is not None
    got = team_preview.replay(seeded, TeamPreviewRequest(horizon_s=5.0, dt_s=1.0), time.monotonic, 60.0)
    assert {m.unit: [s.status for s in m.statuses] for m in got.members} == {
        "a": [DirectionStatus.ARRIVED],
        "b": [DirectionStatus.ARRIVED],
    }
