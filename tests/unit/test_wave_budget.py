"""A wave's share sized by time: a timed ``apply`` steers the batch's own units first, then the wave while its budget lasts.

The driver passes its clock (``World.apply(inputs, now, clock)``); the
world reads it only to stop drawing a wave's units once ``WAVE_BUDGET_S``
past ``now`` is spent, ``WAVE_CHUNK`` at a time, one chunk at least and
``WAVE_PER_TICK`` at most.  The units heard in the batch (the bystanders)
have their directions first; every unit the change reaches is still told
once, nearest first, the direction one pass gives, and its points after.
"""

from __future__ import annotations

import copy
import math

import pytest

from pfp_service.core import PlannerParams
from pfp_service.wire import Goal, ReplanEvent, ThreatUpdate, UnitState
from pfp_service.world import world as world_mod
from pfp_service.world.wave import POINTS_BUDGET_S, POINTS_CHUNK, WAVE_BUDGET_S, WAVE_CHUNK, WAVE_PER_TICK
from pfp_service.world.world import GoalSet, Outputs, StateReported, ThreatPut, Tick, World, WorldSettings

pytestmark = pytest.mark.unit

N = 9 * WAVE_CHUNK + 6
THREAT = ThreatUpdate(position=(20.0, 0.0), facing_deg=270.0, sigma_range=4.0, sigma_lateral=400.0, skew=2.0)
FAR = "z-bystander"  # a unit far behind the threat, out of its reach


class Clock:
    """A driver's clock that moves ``step`` seconds at each read (the world's reads are its only ones)."""

    def __init__(self, t: float, step: float) -> None:
        self.t, self.step, self.reads = t, step, 0

    def __call__(self) -> float:
        self.t += self.step
        self.reads += 1
        return self.t


def _fleet(lookahead: int = 0) -> World:
    """N units in a column along x = 0, each bound east, the threat at (20, 0) facing them; one unit far off."""
    w = World(WorldSettings(planner=PlannerParams(), deliberation="deferred", lookahead=lookahead))
    ids = [f"u{i:03d}" for i in range(N)]
    ys = [(-1) ** i * 3.0 * i for i in range(N)]  # alternately north and south: nearest is not the id order
    w.apply([StateReported(u, UnitState(position=(0.0, y), seq=1)) for u, y in zip(ids, ys)], 0.0)
    w.apply([StateReported(FAR, UnitState(position=(-5_000.0, 0.0), seq=1))], 0.0)
    w.apply([GoalSet(u, Goal(position=(60.0, y))) for u, y in zip(ids, ys)], 0.0)
    w.apply([GoalSet(FAR, Goal(position=(-5_000.0, 60.0)))], 0.0)
    return w


def _follow(w: World, now: float, step: float) -> list[Outputs]:
    outs: list[Outputs] = []
    while w.wave_pending():
        assert len(outs) < 200, "the wave never ends"
        now += 0.002
        outs.append(w.apply([Tick(now, 0)], now, Clock(now, step)))
    return outs


def _wave_units(o: Outputs) -> list[str]:
    return [d.unit for d in o.directions if d.unit != FAR]


@pytest.mark.parametrize(
    ("step", "share"),
    [
        (WAVE_BUDGET_S * 2, WAVE_CHUNK),  # every read past the budget: the one chunk an apply
        (WAVE_BUDGET_S / 2.5, 3 * WAVE_CHUNK),  # read once before each chunk: the third finds it spent
        (0.0, WAVE_PER_TICK),  # a clock that stands still: never past WAVE_PER_TICK
    ],
)
def test_a_timed_apply_draws_the_wave_until_its_budget_is_spent(step: float, share: int):
    w = _fleet()
    one_pass = copy.deepcopy(w)
    first = w.apply([ThreatPut("c", THREAT)], 1.0, Clock(1.0, step))
    (event,) = [e for e in first.events if isinstance(e, ReplanEvent)]
    assert len(event.units) + event.more_units == N  # every unit named at once, however few told
    rest = _follow(w, 1.0, step)
    sizes = [len(_wave_units(o)) for o in [first, *rest]]
    assert len(sizes) > 2 and all(s == share for s in sizes[:-1]) and 0 < sizes[-1] <= share, sizes
    told = [u for o in [first, *rest] for u in _wave_units(o)]
    assert sorted(told) == sorted(f"u{i:03d}" for i in range(N))  # each unit once
    dist = [math.hypot(20.0, 3.0 * int(u[1:])) for u in told]
    assert dist == sorted(dist)  # nearest the threat first
    ref = {d.unit: d for d in one_pass.apply([ThreatPut("c", THREAT)], 1.0).directions}
    ref.update({d.unit: d for o in _follow_untimed(one_pass) for d in o.directions})
    for d in (d for o in [first, *rest] for d in o.directions):
        assert (d.vector, d.status) == (ref[d.unit].vector, ref[d.unit].status)


def _follow_untimed(w: World) -> list[Outputs]:
    outs, now = [], 1.0
    while w.wave_pending():
        now += 0.002
        outs.append(w.apply([Tick(now, 0)], now))
    return outs


def test_the_units_heard_in_the_batch_get_their_directions_before_the_share():
    w = _fleet()
    w.apply([ThreatPut("c", THREAT)], 1.0, Clock(1.0, 0.0))
    heard = [StateReported(FAR, UnitState(position=(-5_000.0, 1.0), seq=2))]
    out = w.apply([*heard, Tick(1.002, 0)], 1.002, Clock(1.002, 0.0))
    assert len(out.directions) > 1 and out.directions[0].unit == FAR and out.directions[0].seq == 2
    assert all(d.unit != FAR for d in out.directions[1:])


def test_with_look_ahead_timed_points_follow_once_every_direction_is_out_and_none_in_the_same_apply():
    step = WAVE_BUDGET_S / 2.5
    w = _fleet(lookahead=3)
    outs = [w.apply([ThreatPut("c", THREAT)], 1.0, Clock(1.0, step)), *_follow(w, 1.0, step)]
    told = {d.unit: k for k, o in enumerate(outs) for d in o.directions if not d.lookahead}
    pointed = {d.unit: k for k, o in enumerate(outs) for d in o.directions if d.lookahead}
    assert set(told) == set(pointed) == {f"u{i:03d}" for i in range(N)}
    assert min(pointed.values()) > max(told.values())  # no points in an apply that told a direction
    per_apply = [sum(1 for d in o.directions if d.lookahead) for o in outs]
    assert max(per_apply) <= world_mod.OWED_PER_TICK and max(per_apply) < N  # in shares, by time


@pytest.mark.parametrize(
    ("step", "share"),
    [
        (POINTS_BUDGET_S * 2, POINTS_CHUNK),  # every read past the points' budget: one chunk an apply
        (POINTS_BUDGET_S / 2.5, 3 * POINTS_CHUNK),  # the third chunk finds it spent
    ],
)
def test_a_waves_points_are_drawn_in_smaller_chunks_on_a_smaller_budget(step: float, share: int):
    w = _fleet(lookahead=3)
    outs = [w.apply([ThreatPut("c", THREAT)], 1.0, Clock(1.0, step)), *_follow(w, 1.0, step)]
    per_apply = [n for o in outs if (n := sum(1 for d in o.directions if d.lookahead))]
    assert sum(per_apply) == N and len(per_apply) > 2, per_apply
    assert all(n == share for n in per_apply[:-1]) and 0 < per_apply[-1] <= share, per_apply
