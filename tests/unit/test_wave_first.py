"""The wave first: a contingency re-directing many units sends their directions before their points and jobs."""

from __future__ import annotations

import copy

import pytest

from pfp_service.core import PlannerParams
from pfp_service.wire import Goal, ThreatUpdate, UnitState
from pfp_service.world import world as world_mod
from pfp_service.world.world import GoalSet, StateReported, ThreatPut, Tick, World, WorldSettings

pytestmark = pytest.mark.unit

T = dict(facing_deg=270.0, sigma_range=4.0, sigma_lateral=3.0, skew=2.0)


@pytest.fixture(autouse=True)
def one_share(monkeypatch):
    """The directions, then the points, each in one apply (their shares: test_wave_shares, test_wave_chunks)."""
    monkeypatch.setattr(world_mod, "WAVE_PER_TICK", 10**6)
    monkeypatch.setattr(world_mod, "OWED_PER_TICK", 10**6)


def _fleet(n: int) -> World:
    w = World(WorldSettings(planner=PlannerParams(escape="auto"), deliberation="deferred"))
    ids = [f"u{i:03d}" for i in range(n)]
    w.apply([StateReported(u, UnitState(position=(0.0, float(i)), seq=1)) for i, u in enumerate(ids)], 0.0)
    w.apply([GoalSet(u, Goal(position=(60.0, float(i)))) for i, u in enumerate(ids)], 0.0)
    return w


def _contingency() -> ThreatPut:
    return ThreatPut("c", ThreatUpdate(position=(20.0, 40.0), **T))


def test_a_wave_sends_directions_first_and_their_points_and_jobs_in_the_next_apply(monkeypatch):
    n = world_mod.WAVE_FIRST + 16
    w = _fleet(n)
    one_pass = copy.deepcopy(w)
    wave = w.apply([_contingency()], 1.0)
    assert len(wave.directions) == n and w.wave_pending()
    assert all(d.lookahead == [] for d in wave.directions) and wave.jobs == []
    after = w.apply([Tick(1.002, 0)], 1.002)
    assert not w.wave_pending()
    assert sorted(d.unit for d in after.directions) == sorted(d.unit for d in wave.directions)
    # the same directions as one pass would give, now with their points; the jobs asked now
    monkeypatch.setattr(world_mod, "WAVE_FIRST", 10 * n)
    ref = one_pass.apply([_contingency()], 1.0)
    by_unit = {d.unit: d for d in after.directions}
    for r, d0 in zip(ref.directions, sorted(wave.directions, key=lambda d: d.unit)):
        d = by_unit[r.unit]
        assert d0.unit == r.unit and d0.vector == r.vector == d.vector and d0.status == r.status
        assert d.lookahead == r.lookahead and len(d.lookahead) > 0
    assert sorted(j.unit for j in after.jobs) == sorted(j.unit for j in ref.jobs) and ref.jobs
    assert w.counts()["deliberating"] == len(ref.jobs)


def test_a_unit_heard_between_the_wave_and_its_points_is_answered_once():
    n = world_mod.WAVE_FIRST + 1
    w = _fleet(n)
    w.apply([_contingency()], 1.0)
    after = w.apply([StateReported("u000", UnitState(position=(0.5, 0.0), seq=2)), Tick(1.002, 0)], 1.002)
    mine = [d for d in after.directions if d.unit == "u000"]
    assert len(mine) == 1 and mine[0].seq == 2 and mine[0].lookahead  # the report's answer, with points
    assert len(after.directions) == n


def test_a_small_change_goes_out_in_one_pass():
    w = _fleet(8)
    out = w.apply([_contingency()], 1.0)
    assert len(out.directions) == 8 and not w.wave_pending()
    assert all(d.lookahead for d in out.directions)
