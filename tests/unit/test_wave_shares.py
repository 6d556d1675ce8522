"""A wave's directions paid in shares: at most ``WAVE_PER_TICK`` units an ``apply``, nearest the change first.

Every unit the change reaches is named in the replan event at once and told
once, in the next applies, the direction one pass would give; a unit heard
meanwhile is answered once, by its report.
"""

from __future__ import annotations

import copy
import math

import pytest

from pfp_service.core import PlannerParams
from pfp_service.wire import Goal, ReplanEvent, ThreatUpdate, UnitState
from pfp_service.world import world as world_mod
from pfp_service.world.world import GoalSet, Outputs, StateReported, ThreatPut, Tick, World, WorldSettings

pytestmark = pytest.mark.unit

SHARE = 16
N = 3 * SHARE + 5
THREAT = ThreatUpdate(position=(20.0, 0.0), facing_deg=270.0, sigma_range=4.0, sigma_lateral=400.0, skew=2.0)


@pytest.fixture
def shares(monkeypatch):
    monkeypatch.setattr(world_mod, "WAVE_PER_TICK", SHARE)


def _fleet(lookahead: int = 0) -> World:
    """N units in a column along x = 0, each bound east; the threat at (20, 0) faces them all."""
    w = World(WorldSettings(planner=PlannerParams(), deliberation="deferred", lookahead=lookahead))
    ids = [f"u{i:03d}" for i in range(N)]
    ys = [(-1) ** i * 3.0 * i for i in range(N)]  # alternately north and south: nearest is not the id order
    w.apply([StateReported(u, UnitState(position=(0.0, y), seq=1)) for u, y in zip(ids, ys)], 0.0)
    w.apply([GoalSet(u, Goal(position=(60.0, y))) for u, y in zip(ids, ys)], 0.0)
    return w


def _follow(w: World, now: float) -> list[Outputs]:
    outs: list[Outputs] = []
    while w.wave_pending():
        assert len(outs) < 100, "the wave never ends"
        now += 0.002
        outs.append(w.apply([Tick(now, 0)], now))
    return outs


def test_a_wave_goes_in_shares_nearest_first_named_at_once_and_gives_what_one_pass_gives(shares, monkeypatch):
    w = _fleet()
    one_pass = copy.deepcopy(w)
    first = w.apply([ThreatPut("c", THREAT)], 1.0)
    (event,) = [e for e in first.events if isinstance(e, ReplanEvent)]
    assert len(event.units) + event.more_units == N  # every unit named, though SHARE told
    assert len(first.directions) == SHARE and w.wave_pending() and w.next_deadline() == 1.0
    rest = _follow(w, 1.0)
    assert [len(o.directions) for o in rest] == [SHARE, SHARE, N - 3 * SHARE]
    told = [d.unit for o in [first, *rest] for d in o.directions]
    assert sorted(told) == sorted(f"u{i:03d}" for i in range(N))  # each unit once
    dist = [math.hypot(20.0, 3.0 * int(u[1:])) for u in told]
    assert dist == sorted(dist)  # nearest the threat first
    monkeypatch.setattr(world_mod, "WAVE_PER_TICK", 10**6)
    ref = {d.unit: d for d in one_pass.apply([ThreatPut("c", THREAT)], 1.0).directions}
    assert len(ref) == N and not one_pass.wave_pending()
    for d in (d for o in [first, *rest] for d in o.directions):
        assert (d.vector, d.status) == (ref[d.unit].vector, ref[d.unit].status)


def test_a_unit_heard_while_owed_is_answered_once_and_a_bystander_at_once(shares):
    w = _fleet()
    w.apply([ThreatPut("c", THREAT)], 1.0)
    last = f"u{N - 1:03d}"  # the farthest: in the last share
    heard = w.apply(
        [StateReported(last, UnitState(position=(0.5, 3.0 * (N - 1) * (-1) ** (N - 1)), seq=2))], 1.002
    )
    mine = [d for d in heard.directions if d.unit == last]
    assert len(mine) == 1 and mine[0].seq == 2  # with the next share, in the same apply
    rest = _follow(w, 1.002)
    assert last not in {d.unit for o in rest for d in o.directions}
    assert len(heard.directions) + sum(len(o.directions) for o in rest) == N - SHARE


def test_with_look_ahead_the_points_follow_once_every_direction_is_out(shares):
    w = _fleet(lookahead=3)
    first = w.apply([ThreatPut("c", THREAT)], 1.0)
    outs = [first, *_follow(w, 1.0)]
    told: dict[str, int] = {}
    for k, o in enumerate(outs):
        for d in o.directions:
            if not d.lookahead:
                told.setdefault(d.unit, k)
    assert len(told) == N  # every unit its direction first, without points
    last_direction = max(told.values())
    pointed = {d.unit: k for k, o in enumerate(outs) for d in o.directions if d.lookahead}
    assert set(pointed) == set(told)  # then each its points
    assert min(pointed.values()) >= last_direction  # no points while a direction of the wave is owed


def test_a_timed_apply_without_its_share_answers_the_batch_alone_and_the_next_draws_it(shares):
    """The node's loop: a tick's states first (``share=False``), then an apply of nothing but the share."""
    w = _fleet()
    clock = iter(range(10**6)).__next__  # a CPU clock that never runs out of budget within one chunk
    w.apply([ThreatPut("c", THREAT)], 1.0, lambda: 0.0)
    owed = w.wave_pending()
    assert owed
    bystander = f"u{N - 1:03d}"
    alone = w.apply([StateReported(bystander, UnitState(position=(0.0, 3.0 * (N - 1) * (-1) ** (N - 1)), seq=2))],
                    1.002, lambda: 0.0, share=False)  # fmt: skip
    assert [d.unit for d in alone.directions] == [bystander]  # no unit of the wave with it
    assert w.wave_pending()
    share = w.apply([], 1.002, lambda: float(clock()))  # the budget spent after one chunk
    assert share.directions and bystander not in {d.unit for d in share.directions}
