"""Team previews with the units outside the team: an outsider crossing the team's way is replayed with it.

The live side is the fleet's simulated vehicles (``pfp_clients.sim.SimUnit``) driven by a live
``World`` with dispersion on; the preview is ``team_preview.replay`` of ``team_preview.seed``.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from pfp_clients.sim import SimUnit

from pfp_service.core import PlannerParams
from pfp_service.team import UnitSpec
from pfp_service.wire import Goal, UnitKind, UnitState
from pfp_service.wire.messages import MAX_PREVIEW_OUTSIDERS, TeamPreviewRequest, TeamUpdate
from pfp_service.world import team_preview
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.team_outsiders import segment_gaps
from pfp_service.world.world import GoalSet, StateReported, TeamPut, World, WorldSettings
from tests.unit.test_team_preview import DT, _live

pytestmark = pytest.mark.unit

TEAM = TeamUpdate(lead="r1", follow=["m1"], standoff_m=30.0, corridor_m=6.0)
FOOT = DispersionSettings(
    enabled=True, default_class="foot"
)  # 5 m apart: a pair feels each other within 10 m


def _fleet(crossing: bool) -> dict[str, SimUnit]:
    specs = [
        UnitSpec(id="r1", start=(6.0, 0.0), goal=(200.0, 0.0), speed_mps=3.0),
        UnitSpec(id="m1", start=(0.0, 0.0), goal=(180.0, 0.0), speed_mps=2.0, kind=UnitKind.MANNED),
        # far from the team's way: never replayed
        UnitSpec(id="z9", start=(0.0, 500.0), goal=(200.0, 500.0), speed_mps=2.0),
    ]
    if crossing:  # manned, and first by id: the members give way to it where their ways cross
        specs.append(
            UnitSpec(id="a1", start=(80.0, -72.0), goal=(80.0, 90.0), speed_mps=2.5, kind=UnitKind.MANNED)
        )
    return {s.id: SimUnit(s, rate_hz=1.0 / DT) for s in specs}


def _started(fleet: dict[str, SimUnit]) -> World:
    w = World(WorldSettings(planner=PlannerParams(intensity="density", step=0.5), dispersion=FOOT))
    w.apply([TeamPut("alpha", TEAM)], 0.0)
    w.apply([StateReported(u.id, u.state(0.0)) for u in fleet.values()], 0.0)
    out = w.apply([GoalSet(u.id, Goal(position=u.spec.goal, tolerance=1.0)) for u in fleet.values()], 0.0)  # type: ignore[arg-type]
    for d in out.directions:
        fleet[d.unit].on_direction(d, 0.0)
    return w


def test_an_outsider_crossing_the_teams_way_is_replayed_and_the_preview_is_what_the_team_then_drives() -> (
    None
):
    fleet = _fleet(crossing=True)
    w = _started(fleet)
    at_s = 5.0
    _live(w, fleet, DT, at_s)
    request = TeamPreviewRequest(horizon_s=200.0, dt_s=DT)
    seeded = team_preview.seed(w, "alpha", at_s, request)
    assert seeded is not None and [m.unit for m in seeded.outsiders] == ["a1"] and seeded.left_out == 0
    got = team_preview.replay(seeded, request, time.monotonic, 60.0)
    assert got.stopped == "arrived" and got.outsiders == ["a1"] and got.outsiders_left_out == 0
    alone = team_preview.replay(dataclasses.replace(seeded, outsiders=()), request, time.monotonic, 60.0)
    assert alone.outsiders == []
    live = _live(w, fleet, round(at_s + DT, 9), at_s + 200.0)
    changed = 0.0
    for m, a in zip(got.members, alone.members, strict=True):
        by_t = {round(t - at_s, 6): (x, y) for t, x, y in live[m.unit]}
        gaps = [math.dist((x, y), by_t[round(t, 6)]) for t, x, y in m.points if round(t, 6) in by_t]
        assert len(gaps) >= len(m.points) - 1
        assert max(gaps) <= 0.01, (m.unit, max(gaps))  # the same code on the same inputs: the same track
        apart = {round(t, 6): (x, y) for t, x, y in a.points}
        changed = max(
            changed,
            max(math.dist((x, y), apart[round(t, 6)]) for t, x, y in m.points if round(t, 6) in apart),
        )
    print(f"the crossing outsider moved a member's track by up to {changed:.2f} m")
    assert changed > 1.0  # without it the preview would have been wrong by that much


def test_outsiders_are_taken_nearest_first_up_to_the_cap_and_the_rest_counted() -> None:
    fleet = _fleet(crossing=False)
    w = _started(fleet)
    extra = MAX_PREVIEW_OUTSIDERS + 6
    # parked beside the team's way (no goal: they stand), the higher the index the nearer
    w.apply(
        [
            StateReported(f"p{k:03d}", UnitState(position=(100.0, 9.0 - k * 0.1), speed_mps=0.0))
            for k in range(extra)
        ],
        0.0,
    )
    seeded = team_preview.seed(w, "alpha", 0.0, TeamPreviewRequest(speeds={"r1": 3.0, "m1": 2.0}))
    assert seeded is not None
    taken = [m.unit for m in seeded.outsiders]
    assert len(taken) == MAX_PREVIEW_OUTSIDERS and seeded.left_out == 6
    assert taken == [f"p{k:03d}" for k in range(extra - 1, 5, -1)]  # nearest (smallest |y|) first
    assert "z9" not in taken and all(m.goal is None and m.stepper is None for m in seeded.outsiders)
    got = team_preview.replay(
        seeded, TeamPreviewRequest(horizon_s=2.0, speeds={"r1": 3.0, "m1": 2.0}), time.monotonic, 30.0
    )
    assert got.outsiders == taken and got.outsiders_left_out == 6
    # with dispersion off no outsider changes a member's way: none is taken
    off = World(WorldSettings(planner=PlannerParams(intensity="density", step=0.5)))
    off.apply([TeamPut("alpha", TEAM)], 0.0)
    off.apply([StateReported(u.id, u.state(0.0)) for u in fleet.values()], 0.0)
    plain = team_preview.seed(off, "alpha", 0.0)
    assert plain is not None and plain.outsiders == () and plain.left_out == 0


def test_the_gap_between_two_segments_is_shapelys() -> None:
    shapely = pytest.importorskip("shapely")
    rng = np.random.default_rng(33)
    print("seed 33")
    a = rng.uniform(-50.0, 50.0, (200, 4))
    a[:20, 2:] = a[:20, :2]  # points: a unit that stands
    b = rng.uniform(-50.0, 50.0, (3, 4))
    got = segment_gaps(a, b)
    for i in range(len(a)):
        p = shapely.LineString([a[i, :2], a[i, 2:]]) if i >= 20 else shapely.Point(a[i, :2])
        for j in range(len(b)):
            want = p.distance(shapely.LineString([b[j, :2], b[j, 2:]]))
            assert got[i, j] == pytest.approx(want, abs=1e-9), (i, j)


def test_an_outsider_is_taken_when_its_reach_over_the_horizon_comes_near_the_teams() -> None:
    fleet = _fleet(crossing=False)
    far = UnitSpec(id="b2", start=(100.0, 300.0), goal=(100.0, -300.0), speed_mps=2.0)
    fleet["b2"] = SimUnit(far, rate_hz=1.0 / DT)
    w = _started(fleet)
    _live(w, fleet, DT, 2.0)  # every unit has reported moving: its speed is known
    speeds = {"r1": 3.0, "m1": 2.0}
    soon = team_preview.seed(w, "alpha", 2.0, TeamPreviewRequest(horizon_s=60.0, speeds=speeds))
    later = team_preview.seed(w, "alpha", 2.0, TeamPreviewRequest(horizon_s=200.0, speeds=speeds))
    assert soon is not None and later is not None
    assert [m.unit for m in soon.outsiders] == []  # 120 m in 60 s: still 180 m off the team's way
    (b2,) = later.outsiders  # 400 m in 200 s: across it
    assert b2.unit == "b2" and b2.params is not None and b2.stepper is None and b2.speed_mps == 2.0
