"""Dispersion's deadlocks, crowded goals and team separations (issue 33), measured on the tracks.

The crowds are driven through the sans-I/O world in process (``benchmarks._crowd.simulate``);
separations are checked against the documented rule, written out here, not taken from the product.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import _crowd
from pfp_service.wire import DeadlockEvent, DirectionStatus, TeamUpdate
from pfp_service.world.separations import DispersionSettings

pytestmark = pytest.mark.unit

ON = DispersionSettings(enabled=True)


def _closest_share(tracks: list[np.ndarray], sep_of) -> float:  # type: ignore[no-untyped-def]
    """The least distance over separation of any pair at any tick, ``sep_of(t, i, j)`` the pair's separation."""
    worst = math.inf
    for t, pos in enumerate(tracks):
        for i in range(len(pos)):
            for j in range(i + 1, len(pos)):
                worst = min(worst, float(np.hypot(*(pos[i] - pos[j]))) / sep_of(t, i, j))
    return worst


@pytest.mark.parametrize("crowd", [_crowd.pinned(), _crowd.head_on()], ids=["pinned in a gap", "head on"])
def test_a_deadlock_is_detected_and_cleared_within_30_s(crowd):
    tracks: list = []
    locks: list = []
    record: list = []
    out = _crowd.simulate(crowd, ON, tracks=tracks, locks=locks, record=record)
    assert locks, "the case is a real one: a deadlock arises"
    assert all(isinstance(e, DeadlockEvent) and e.held_s >= ON.deadlock_s for _, e in locks)
    assert (
        out.not_cleared == 0 and 0.0 < out.longest_clearing_s <= 30.0
    )  # on the tracks: both nearer their goals
    assert out.longest_deadlock_s <= 30.0 and out.still_holding == 0
    assert set(out.arrived_s) == set(crowd.ids())
    assert _closest_share(tracks, lambda t, i, j: 50.0) >= 0.9
    said = {d.reason.split(" ")[0] for _, d in record if d.status is DirectionStatus.YIELDING}
    assert said <= {"yielding", "backing", "going"}


def test_a_unit_goes_round_a_unit_at_rest_on_its_goal_side():
    record: list = []
    locks: list = []
    _crowd.simulate(_crowd.pinned(), ON, record=record, locks=locks)
    assert [(e.unit, e.other) for _, e in locks][:1] == [("u0001", "u0000")]  # the one at rest does not move
    rounds = [d for _, d in record if d.unit == "u0001" and "going round u0000 (arrived)" in d.reason]
    assert rounds and all(d.vector[1] > -0.5 for d in rounds)  # round it, towards the goal: not back


def _relaxed(s: float, gap: float, far: float) -> float:
    """The documented rule: near a shared goal a pair keeps 0.6 of their goals' gap, relaxing over 2 separations."""
    floor = min(s, 0.6 * gap)
    return floor + (s - floor) * min(far / (2.0 * s), 1.0)


def test_a_crowded_goal_area_every_unit_arrives_and_keeps_its_relaxed_separation():
    crowd = _crowd.crowded_goal(8, 20.0)
    goals = np.array(crowd.goals)
    assert np.hypot(*(goals[0] - goals[1])) < 50.0  # closer than the separation: unreachable unrelaxed
    tracks: list = []
    out = _crowd.simulate(crowd, ON, tracks=tracks)
    assert set(out.arrived_s) == set(crowd.ids()), f"arrived: {sorted(out.arrived_s)}"

    def sep(t: int, i: int, j: int) -> float:
        far = max(np.hypot(*(tracks[t][i] - goals[i])), np.hypot(*(tracks[t][j] - goals[j])))
        return _relaxed(50.0, float(np.hypot(*(goals[i] - goals[j]))), float(far))

    assert _closest_share(tracks, sep) >= 0.9
    assert _closest_share(tracks[:5], lambda t, i, j: 50.0) >= 1.0  # far from the goals: the full separation


def test_a_team_keeps_its_separation_m_among_its_members_and_by_class_with_others():
    base = _crowd.head_on()
    crowd = _crowd.Crowd(
        "a team of two and one other",
        starts=[(0.0, 0.0), (0.0, 300.0), (40.0, 150.0)],
        goals=[(0.0, 600.0), (0.0, -300.0), (40.0, 800.0)],
        kinds=["manned", "unmanned", "unmanned"],
        threats={},
        limit_s=base.limit_s,
        teams={"alpha": TeamUpdate(members=["u0000", "u0001"], separation_m=120.0)},
    )
    tracks: list = []
    out = _crowd.simulate(crowd, ON, tracks=tracks)
    assert set(out.arrived_s) == set(crowd.ids())
    gap_team = min(float(np.hypot(*(p[0] - p[1]))) for p in tracks)
    assert gap_team >= 0.9 * 120.0  # the team's, not the class's 50 m
    assert _closest_share(tracks, lambda t, i, j: 120.0 if {i, j} == {0, 1} else 50.0) >= 0.9
    plain = _crowd.Crowd(crowd.name, crowd.starts, crowd.goals, crowd.kinds, {}, limit_s=base.limit_s)
    untouched: list = []
    _crowd.simulate(plain, ON, tracks=untouched)
    assert min(float(np.hypot(*(p[0] - p[1]))) for p in untouched) < 0.9 * 120.0  # the case is a real one


@pytest.mark.parametrize("seed", [0, 1])
def test_the_index_with_teams_and_goals_gives_what_every_pair_gives(seed):
    from pfp_service.core.dispersion import NeighbourIndex, brute_gradients, pair_separation

    rng = np.random.default_rng(seed)
    n = 300
    pts = rng.uniform(-1000, 1000, (n, 2))
    seps = rng.choice([5.0, 50.0], n)
    team = rng.choice([-1, 0, 1], n)
    team_sep = np.where(team == 0, 120.0, np.where(team == 1, 20.0, np.nan))
    goals = np.where(rng.random((n, 1)) < 0.5, pts + rng.uniform(-60, 60, (n, 2)), np.nan)
    index = NeighbourIndex(pts, seps, team, team_sep, goals)
    got = index.gradients(np.arange(n))
    np.testing.assert_allclose(got, brute_gradients(pts, seps, team, team_sep, goals), rtol=1e-12, atol=1e-15)
    i, j = np.array([0, 1, 2]), np.array([3, 4, 5])
    for a, b, s in zip(i, j, pair_separation(pts, seps, i, j, team, team_sep, goals)):
        want = (
            120.0 if team[a] == team[b] == 0 else 20.0 if team[a] == team[b] == 1 else max(seps[a], seps[b])
        )
        if np.isfinite(goals[a]).all() and np.isfinite(goals[b]).all():
            far = max(np.hypot(*(pts[a] - goals[a])), np.hypot(*(pts[b] - goals[b])))
            want = _relaxed(want, float(np.hypot(*(goals[a] - goals[b]))), float(far))
        assert s == pytest.approx(want)
    assert index.radius == 2.0 * 120.0  # the widest pair is felt: the team's, not the class's


def test_a_hostile_team_separation_is_kept_only_up_to_its_bound():
    from pfp_service.wire import Goal, UnitKind, UnitState
    from pfp_service.world import events as ev
    from pfp_service.world.world import World, WorldSettings

    w = World(WorldSettings(deliberation="deferred", dispersion=ON))
    far = [(f"u{k}", (3000.0 * k, 0.0)) for k in range(4)]
    states = [ev.StateReported(u, UnitState(position=p, kind=UnitKind.UNMANNED)) for u, p in far]
    w.apply(
        [*states, ev.TeamPut("big", TeamUpdate(members=[u for u, _ in far], separation_m=100_000.0))], 0.0
    )
    w.apply([ev.GoalSet(u, Goal(position=(p[0], 900.0))) for u, p in far], 0.5)
    out = w.apply(states, 1.0)
    assert [e for e in out.events if type(e).__name__ == "RejectedEvent"] == []
    assert {d.status for d in out.directions} == {DirectionStatus.EN_ROUTE}
    assert all(abs(d.vector[0]) < 1e-9 for d in out.directions)  # 3 km apart: no push, straight north
