"""A window's landing judged off the loop: the sight thread tests the put's corridors with the window it computed.

The put's ask carries the units' corridors as they stood (``wave.Corridors``);
``wave.answered`` lands the window with their reach (``wave.Judged``), and the
landing re-tests only the units whose corridor changed since.  What goes out
is what the landing would give testing every unit itself.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from pfp_service.core import PlannerParams
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.live import of_grid
from pfp_service.wire import Goal, ReplanEvent, ThreatUpdate, UnitState
from pfp_service.world import reach, wave
from pfp_service.world.terrain import answer
from pfp_service.world.world import GoalSet, StateReported, ThreatPut, World, WorldSettings

pytestmark = pytest.mark.unit

# behind a ridge along x = 0: from (-1000, 0) it sees the units west of the ridge, not those east of it
BEHIND = ThreatUpdate(position=(-1000.0, 0.0), facing_deg=90.0, sigma_range=800.0, sigma_lateral=800.0)
XS = [-700.0, -500.0, -300.0, 600.0, 800.0, 1000.0]
GROUND = of_grid(
    TerrainGrid(
        -3000.0,
        -3000.0,
        20.0,
        np.maximum(0.0, 60.0 - 0.2 * np.abs(np.meshgrid(np.linspace(-3000.0, 3000.0, 301), [0.0] * 301)[0])),
    )
)


def _world() -> World:
    s = WorldSettings(planner=PlannerParams(), deliberation="deferred", terrain=GROUND, lookahead=0)
    w = World(s)
    for i, x in enumerate(XS):
        w.apply([StateReported(f"u{i}", UnitState(position=(x, -300.0), seq=1))], 0.0)
        w.apply([GoalSet(f"u{i}", Goal(position=(x, 300.0)))], 0.0)
    return w


def _told(out) -> tuple[list[str], dict[str, tuple]]:
    (replan,) = [e for e in out.events if isinstance(e, ReplanEvent)]
    return sorted(replan.units), {d.unit: (d.vector, d.status) for d in out.directions}


def _both(meanwhile=()):
    """The same put landed in two worlds: judged off the loop, and tested on the loop (no verdict)."""
    off, on = _world(), _world()
    (ask,) = off.apply([ThreatPut("t", BEHIND)], 1.0).sights
    (ask_on,) = on.apply([ThreatPut("t", BEHIND)], 1.0).sights
    assert isinstance(ask.corridors, wave.Corridors) and len(ask.corridors.ids) == len(XS)
    landed = wave.answered(GROUND, ask)
    assert isinstance(landed.judged, wave.Judged)
    for w in (off, on):
        w.apply(list(meanwhile), 1.01)
    return off, on, landed, answer(GROUND, ask_on)


def test_a_landing_judged_off_the_loop_tells_the_units_the_loop_would():
    off, on, landed, plain = _both()
    assert plain.judged is None
    got, want = _told(off.apply([landed], 1.02)), _told(on.apply([plain], 1.02))
    assert got == want
    assert got[0] == ["u0", "u1", "u2"]  # the units west of the ridge: the threat sees them only


def test_a_unit_moved_into_sight_since_the_ask_is_tested_again_and_only_it(monkeypatch):
    moved = StateReported("u4", UnitState(position=(-400.0, -300.0), seq=2))  # east, hidden -> west, seen
    off, on, landed, plain = _both([moved])
    rows: list[int] = []
    real = reach.reached_at

    def counted(flat, *a, **k):
        rows.append(len(flat))
        return real(flat, *a, **k)

    monkeypatch.setattr(reach, "reached_at", counted)
    got = _told(off.apply([landed], 1.02))
    assert rows == [1], "the landing tested more than the unit moved since the ask"
    assert got == _told(on.apply([plain], 1.02))
    assert "u4" in got[0]


def test_a_verdict_for_a_threat_put_again_meanwhile_is_not_taken():
    off, on, landed, plain = _both()
    again = copy.deepcopy(BEHIND)  # the same place: no new ask, the record held is the newer one
    for w in (off, on):
        assert not w.apply([ThreatPut("t", again)], 1.01).sights
    assert _told(off.apply([landed], 1.02)) == _told(on.apply([plain], 1.02))


def test_a_judge_that_fails_lands_no_verdict_and_a_test_that_fails_on_landing_reaches_every_unit(monkeypatch):
    moved = StateReported("u4", UnitState(position=(-400.0, -300.0), seq=2))
    off, _on, landed, _plain = _both([moved])
    (ask,) = _world().apply([ThreatPut("t", BEHIND)], 1.0).sights

    def broken(*a, **k):
        raise FloatingPointError("a corridor the field cannot read")

    monkeypatch.setattr(reach, "reached_at", broken)
    assert wave.answered(GROUND, ask).judged is None  # the world's landing tests every unit then
    assert _told(off.apply([landed], 1.02))[0] == [f"u{i}" for i in range(len(XS))]  # dearer, never wrong


def test_a_storm_of_puts_takes_the_corridors_once_and_each_ask_names_the_threat_it_replaces():
    w = _world()
    (first,) = w.apply([ThreatPut("t", BEHIND)], 1.0).sights
    w.apply([wave.answered(GROUND, first)], 1.01)
    moved = ThreatUpdate(position=(-1000.0, 50.0), facing_deg=90.0, sigma_range=800.0, sigma_lateral=800.0)
    other = ThreatUpdate(position=(-1000.0, -50.0), facing_deg=90.0, sigma_range=800.0, sigma_lateral=800.0)
    asks = w.apply([ThreatPut("t", moved), ThreatPut("o", other)], 1.02).sights
    assert [a.threat for a in asks] == ["t", "o"]
    assert asks[0].corridors.ends is asks[1].corridors.ends  # one snapshot for the batch
    assert asks[0].corridors.before is w.records.threats["t"].threat and asks[1].corridors.before is None
    assert asks[0].corridors.before_window is not None  # the window it is seen through now
