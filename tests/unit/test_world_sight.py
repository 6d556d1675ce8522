"""A threat put over terrain: its sight computed off the loop, never in ``World.apply`` (issue 32).

The world holds a threat whose window has not landed and asks for it
(``Outputs.sights``); only the window landed (``SightLanded``) puts it in
force, and then only the units it can see are re-directed.  A window that
never lands puts the threat in force blind after ``sight_wait_s``.
"""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.core import PlannerParams
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.live import of_grid
from pfp_service.wire import Goal, ReplanEvent, ThreatUpdate, UnitState
from pfp_service.world.terrain import answer
from pfp_service.world.world import (
    GoalSet,
    SightLanded,
    StateReported,
    ThreatPut,
    ThreatRemoved,
    Tick,
    World,
    WorldSettings,
)

pytestmark = pytest.mark.unit

# behind a ridge along x = 0: from (-1000, 0) it sees the units west of the ridge, not east of it
BEHIND = ThreatUpdate(position=(-1000.0, 0.0), facing_deg=90.0, sigma_range=800.0, sigma_lateral=800.0)
UNITS = {"front": -500.0, "valley": 600.0}


class Counted:
    """A ground that counts its sweeps: the world must never call it while deliberating off the loop."""

    def __init__(self, ground) -> None:
        self.ground, self.calls = ground, 0
        self.zones, self.resolution_m = ground.zones, ground.resolution_m

    def sees(self, a, b, clearance_m: float = 0.0) -> bool:  # a controller's link: not a sweep
        return self.ground.sees(a, b, clearance_m)

    def __call__(self, threat, box):
        self.calls += 1
        return self.ground(threat, box)


def _ridge(side: int = 301) -> TerrainGrid:
    xs = np.linspace(-3000.0, 3000.0, side)
    gx, _ = np.meshgrid(xs, xs)
    return TerrainGrid(-3000.0, -3000.0, xs[1] - xs[0], np.maximum(0.0, 60.0 - 0.2 * np.abs(gx)))


def _world(ground, wait_s: float = 0.25) -> World:
    s = WorldSettings(
        planner=PlannerParams(), deliberation="deferred", terrain=ground, sight_wait_s=wait_s, lookahead=0
    )
    w = World(s)
    for uid, x in UNITS.items():
        w.apply([StateReported(uid, UnitState(position=(x, -300.0), seq=1))], 0.0)
        w.apply([GoalSet(uid, Goal(position=(x, 300.0)))], 0.0)
    return w


def _replans(out) -> list[ReplanEvent]:
    return [e for e in out.events if isinstance(e, ReplanEvent)]


def test_a_put_is_held_and_asked_the_sweep_never_runs_in_apply_and_the_window_redirects_only_the_seen():
    ground = Counted(of_grid(_ridge()))
    w = _world(ground)
    out = w.apply([ThreatPut("t", BEHIND)], 1.0)
    assert ground.calls == 0, "the viewshed sweep ran inside World.apply"
    (ask,) = out.sights
    assert ask.threat == "t" and not out.directions and not _replans(out)  # held: nothing changed yet
    assert len(w.field.threats) == 0 and w.next_deadline() == pytest.approx(1.25)
    # the same put again while its window is on its way: no second ask
    assert not w.apply([ThreatPut("t", BEHIND)], 1.05).sights
    landed = answer(ground, ask)  # what the node's thread does
    assert ground.calls == 1
    out = w.apply([landed], 1.1)
    (replan,) = _replans(out)
    assert replan.units == ["front"], replan  # the valley's unit, hidden by the ridge, keeps its direction
    assert [d.unit for d in out.directions] == ["front"]
    assert len(w.field.threats) == 1 and ground.calls == 1
    # a later window for the same key changes nothing; the timer finds nothing held
    assert not _replans(w.apply([landed, Tick(2.0)], 2.0))
    # put back where it stood: in force at once, no ask
    out = w.apply([ThreatPut("t", BEHIND)], 3.0)
    assert not out.sights and _replans(out)[0].units == ["front"] and ground.calls == 1


def test_a_window_that_never_lands_puts_the_threat_in_force_blind_then_masks_it_when_it_does():
    ground = Counted(of_grid(_ridge()))
    w = _world(ground, wait_s=0.1)
    (ask,) = w.apply([ThreatPut("t", BEHIND)], 1.0).sights
    assert not _replans(w.apply([Tick(1.05)], 1.05))
    out = w.apply([Tick(1.1)], 1.1)  # given up: blind, the safe side, so both units are re-directed
    assert sorted(_replans(out)[0].units) == ["front", "valley"] and len(w.field.threats) == 1
    late = answer(ground, ask)
    w.apply([ThreatPut("t", BEHIND)], 1.15)  # put again where it stands, still blind: no second ask
    out = w.apply([late], 1.2)  # masked now: re-judged as a put, the units it sees
    assert _replans(out)[0].units == ["front"]
    valley = w.field.level(np.array([[600.0, 0.0]]))[0]
    assert valley < 1e-6, valley
    assert ground.calls == 1


def test_a_window_for_a_threat_moved_or_removed_meanwhile_is_dropped():
    ground = Counted(of_grid(_ridge()))
    w = _world(ground)
    (first,) = w.apply([ThreatPut("t", BEHIND)], 1.0).sights
    moved = ThreatUpdate(position=(-900.0, 0.0), facing_deg=90.0, sigma_range=800.0, sigma_lateral=800.0)
    (second,) = w.apply([ThreatPut("t", moved)], 1.01).sights
    assert first.key != second.key
    out = w.apply([answer(ground, first)], 1.02)
    assert not out.directions and len(w.field.threats) == 0  # the newer put still waits for its own
    assert _replans(w.apply([answer(ground, second)], 1.03))[0].units == ["front"]
    (third,) = w.apply([ThreatPut("t", BEHIND)], 1.04).sights  # moved back: its first window was kept
    w.apply([ThreatRemoved("t")], 1.05)
    out = w.apply([answer(ground, third), Tick(2.0)], 2.0)
    assert not _replans(out) and len(w.field.threats) == 0


def test_a_world_deliberating_inline_computes_the_window_at_once():
    ground = Counted(of_grid(_ridge()))
    w = World(WorldSettings(terrain=ground, lookahead=0))
    for uid, x in UNITS.items():
        w.apply([StateReported(uid, UnitState(position=(x, -300.0), seq=1))], 0.0)
        w.apply([GoalSet(uid, Goal(position=(x, 300.0)))], 0.0)
    out = w.apply([ThreatPut("t", BEHIND)], 1.0)
    assert not out.sights and ground.calls == 1 and _replans(out)[0].units == ["front"]


def test_a_window_landing_in_a_world_without_terrain_is_ignored():
    w = World(WorldSettings(lookahead=0))
    out = w.apply([SightLanded("t", (0.0,), None)], 1.0)
    assert not out.directions and not out.faults and len(w.field.threats) == 0


def test_a_big_grid_put_stays_off_the_sweep():
    """1,001 x 1,001 cells of 10 m under a 5 km reach: the put costs its packing, never the sweep."""
    ground = Counted(of_grid(_ridge(1001)))
    w = _world(ground)
    big = ThreatUpdate(position=(-1000.0, 0.0), facing_deg=90.0, sigma_range=2200.0, sigma_lateral=2200.0)
    out = w.apply([ThreatPut("big", big)], 1.0)
    assert ground.calls == 0 and len(out.sights) == 1
