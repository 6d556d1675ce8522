"""A wave's follow-up paid in chunks: at most ``OWED_PER_TICK`` units' points and jobs an ``apply``, as one pass gives."""

from __future__ import annotations

import copy

import pytest

from pfp_service.core import PlannerParams
from pfp_service.wire import Goal, ThreatUpdate, UnitState
from pfp_service.world import world as world_mod
from pfp_service.world.world import (
    GoalSet,
    Outputs,
    StateReported,
    ThreatPut,
    ThreatRemoved,
    Tick,
    World,
    WorldSettings,
)

pytestmark = pytest.mark.unit

# wide across: it reaches every unit's corridor, deliberating or not (``reach.reached``), so the wave is all n
T = dict(facing_deg=270.0, sigma_range=4.0, sigma_lateral=40.0, skew=2.0)
CHUNK = 16


@pytest.fixture
def chunked(monkeypatch):
    monkeypatch.setattr(world_mod, "OWED_PER_TICK", CHUNK)
    monkeypatch.setattr(
        world_mod, "WAVE_PER_TICK", 10**6
    )  # the directions in one apply: ``test_wave_shares``


def _fleet(n: int) -> World:
    w = World(WorldSettings(planner=PlannerParams(escape="auto"), deliberation="deferred"))
    ids = [f"u{i:03d}" for i in range(n)]
    w.apply([StateReported(u, UnitState(position=(0.0, float(i)), seq=1)) for i, u in enumerate(ids)], 0.0)
    w.apply([GoalSet(u, Goal(position=(60.0, float(i)))) for i, u in enumerate(ids)], 0.0)
    return w


def _put(tid: str = "c", y: float = 40.0) -> ThreatPut:
    return ThreatPut(tid, ThreatUpdate(position=(20.0, y), **T))


def _follow(w: World, now: float, limit: int = 100) -> list[Outputs]:
    outs: list[Outputs] = []
    while w.wave_pending():
        assert len(outs) < limit, "the follow-up never ends"
        now += 0.002
        outs.append(w.apply([Tick(now, 0)], now))
    return outs


def test_the_follow_up_goes_in_chunks_and_gives_what_one_pass_gives(chunked, monkeypatch):
    n = world_mod.WAVE_FIRST + 3 * CHUNK + 5
    w = _fleet(n)
    one_pass = copy.deepcopy(w)
    wave = w.apply([_put()], 1.0)
    assert len(wave.directions) == n and all(d.lookahead == [] for d in wave.directions)
    follow = _follow(w, 1.0)
    assert len(follow) == -(-n // CHUNK)  # every chunk full but the last
    assert all(len(o.directions) <= CHUNK for o in follow) and len(follow[-1].directions) == n % CHUNK
    units = [d.unit for o in follow for d in o.directions]
    assert sorted(units) == sorted(d.unit for d in wave.directions)  # each unit once
    assert units == sorted(units)  # in the wave's order
    monkeypatch.setattr(world_mod, "WAVE_FIRST", 10 * n)
    ref = one_pass.apply([_put()], 1.0)
    assert not one_pass.wave_pending()
    by_unit = {d.unit: d for o in follow for d in o.directions}
    for r in ref.directions:
        d = by_unit[r.unit]
        assert (d.vector, d.status, d.lookahead, d.deliberating) == (
            r.vector,
            r.status,
            r.lookahead,
            r.deliberating,
        )
        assert d.lookahead
    jobs = sorted(j.unit for o in follow for j in o.jobs)
    assert jobs == sorted(j.unit for j in ref.jobs) and jobs
    assert w.counts()["deliberating"] == one_pass.counts()["deliberating"] == len(jobs)


def test_a_unit_heard_while_its_chunk_waits_is_answered_once(chunked):
    n = world_mod.WAVE_FIRST + 3 * CHUNK
    w = _fleet(n)
    w.apply([_put()], 1.0)
    last = f"u{n - 1:03d}"  # in the last chunk
    heard = w.apply(
        [StateReported(last, UnitState(position=(0.5, float(n - 1)), seq=2)), Tick(1.002, 0)], 1.002
    )
    mine = [d for d in heard.directions if d.unit == last]
    assert len(mine) == 1 and mine[0].seq == 2 and mine[0].lookahead
    rest = _follow(w, 1.002)
    assert last not in {d.unit for o in rest for d in o.directions}
    assert len(heard.directions) - 1 + sum(len(o.directions) for o in rest) == n - 1


def test_a_second_wave_while_a_follow_up_is_owed_leaves_no_unit_without_its_points(chunked):
    n = world_mod.WAVE_FIRST + 4 * CHUNK
    w = _fleet(n)
    w.apply([_put()], 1.0)
    w.apply([Tick(1.002, 0)], 1.002)  # one chunk paid, the rest owed
    assert w.wave_pending()
    second = w.apply([ThreatRemoved("c")], 1.004)  # reaches them all again
    assert len(second.directions) == n
    latest = {d.unit: d for d in second.directions}
    for out in _follow(w, 1.004):
        for d in out.directions:
            assert d.vector == latest[d.unit].vector and not latest[d.unit].lookahead  # the second's advice
            latest[d.unit] = d
    assert all(d.lookahead for d in latest.values())
    assert not w.wave_pending()


def test_the_bench_times_every_follow_up_apply(monkeypatch):
    from benchmarks._deliberation import storm_and_wave

    monkeypatch.setattr(world_mod, "WAVE_FIRST", 4)
    monkeypatch.setattr(world_mod, "OWED_PER_TICK", 5)
    wave = storm_and_wave(units=24, repeat=1)["wave"]
    assert wave["directions"] > 4
    assert wave["then_ticks"] == -(-wave["directions"] // 5)
    assert 0.0 < wave["then_apply_ms_median"] <= wave["then_apply_ms_max"]
    assert wave["held_off_gc_ms_median"] >= 0.0
