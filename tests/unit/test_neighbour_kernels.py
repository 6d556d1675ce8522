"""A tick's fixed cost, compiled: the same numbers as the NumPy they stand for (issue 33, "Cost").

``NeighbourIndex``'s few rows' neighbours on a kept tree (``neighbour_kernels.within``) are those the tree,
widened by its slack, finds and the tree's test keeps; its pairs' separations (``pair_seps``) are
``pair_separation``'s and its gradients (``pair_terms``) ``_pair_terms``', bit for bit.  Right of way's
nearest blocker (``right_of_way.blockers``, its few close pairs read off their records) is the one the
arrays over the fleet found, at every tick of a crowd.
"""

from __future__ import annotations

import math
import random
from collections.abc import Container
from typing import Any

import numpy as np
import pytest

from pfp_service.core import dispersion, polyline_kernels
from pfp_service.core.dispersion import NeighbourIndex, pair_separation
from pfp_service.wire import Goal, UnitKind, UnitState
from pfp_service.world import deadlocks, right_of_way
from pfp_service.world import dispersion as world_dispersion
from pfp_service.world import teams as roles
from pfp_service.world.events import GoalSet, StateReported
from pfp_service.world.right_of_way import AHEAD, FOLLOW, YIELD_AT, priority
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.world import World, WorldSettings

pytestmark = pytest.mark.unit


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


@pytest.mark.parametrize("seed", range(8))
def test_a_kept_trees_rows_are_what_the_widened_tree_keeps(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 600
    before = rng.uniform(0.0, 2_000.0, size=(n, 2))
    seps = rng.choice([5.0, 50.0], n)
    before[5] = before[6]  # two on one point
    before[9] = before[10] + (dispersion.REACH * 50.0, 0.0)  # exactly at the reach
    first = NeighbourIndex(before, seps)
    after = before.copy()
    moved = np.setdiff1d(rng.choice(n, size=60, replace=False), [5, 6, 9, 10])
    after[moved] += rng.uniform(-15.0, 15.0, size=(len(moved), 2))
    kept = NeighbourIndex(after, seps, moved_from=first)
    assert kept.tree is first.tree and kept._slack > 0.0
    rows = sorted({5, 9, 10, *rng.choice(n, size=40, replace=False).tolist()})
    # the plain computation: the kept tree's query widened by its slack, measured with its test
    wide = first.tree.query_ball_point(after[rows], kept.radius + kept._slack, return_sorted=True)
    want = [
        [
            j
            for j in got
            if (after[r, 0] - after[j, 0]) ** 2 + (after[r, 1] - after[j, 1]) ** 2 <= kept.radius**2
        ]
        for r, got in zip(rows, wide, strict=True)
    ]
    assert kept._found(np.array(rows)) == want
    fresh = NeighbourIndex(after, seps)  # and what a tree built on these points finds
    assert fresh._found(np.array(rows)) == want


@pytest.mark.parametrize("seed", range(10))
def test_pair_seps_are_pair_separations(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 300))
    pts = rng.uniform(-3_000.0, 3_000.0, (n, 2))
    seps = rng.choice([5.0, 20.0, 50.0], n)
    team = rng.integers(-1, 5, n).astype(np.intp) if seed % 3 else None
    team_sep = np.where(team >= 0, rng.choice([10.0, 60.0, 0.0], n), math.nan) if team is not None else None
    goals = None
    if seed % 2:
        goals = pts + rng.normal(0.0, float(rng.choice([1.0, 50.0, 500.0])), (n, 2))
        goals[rng.random(n) < 0.2] = math.nan  # without a goal
        goals[: n // 3] = goals[0]  # a shared goal: the separation relaxes
    i, j = rng.integers(0, n, 500), rng.integers(0, n, 500)
    index = NeighbourIndex(pts, seps, team, team_sep, goals)
    with np.errstate(all="ignore"):  # a team's separation of 0: NaN and inf, as the kernel's
        want = pair_separation(pts, seps, i, j, team, team_sep, goals)
    assert _same(index.pair_seps(i, j), want)


@pytest.mark.parametrize("seed", range(10))
def test_gradients_are_the_pairs_terms(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 400))
    pts = rng.uniform(0.0, float(rng.choice([300.0, 3_000.0])), (n, 2))
    if seed % 4 == 0:
        pts[: n // 3] = pts[0]  # on one point: the lower row goes west
    seps = rng.choice([5.0, 20.0, 50.0], n)
    index = NeighbourIndex(pts, seps, goals=pts + rng.normal(0.0, 100.0, (n, 2)) if seed % 2 else None)
    rows = np.unique(rng.integers(0, n, int(rng.integers(1, n + 1))))
    got = index.gradients(rows)
    i, j, pair_s = index.near_seps(rows)
    gx, gy = dispersion._pair_terms(index.points, pair_s, i, j, n)
    assert np.array_equal(got, np.column_stack([gx[rows], gy[rows]]))


def _blockers_over_the_fleet(
    index: NeighbourIndex,
    all_recs: list,
    held: Container[str],
    manned_first: bool,
    moving: list,
    rows: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``right_of_way.blockers`` as it was: right of way's order, who goes and their ways as arrays over the fleet."""
    vec = np.array([d.vector for d in moving], dtype=float).reshape(-1, 2)
    at = np.full(len(all_recs), -1, dtype=np.intp)
    at[rows] = np.arange(len(rows))
    i, j, pair_s = index.near_seps(rows)
    rel = index.points[j] - index.points[i]
    gap = np.hypot(rel[:, 0], rel[:, 1])
    along = (rel * vec[at[i]]).sum(axis=1)
    close = (along > 0.0) & (gap < YIELD_AT * pair_s)
    i, j, gap, along, rel, pair_s = i[close], j[close], gap[close], along[close], rel[close], pair_s[close]
    n = len(all_recs)
    used = np.unique(np.concatenate([i, j]))
    recs = [all_recs[u] for u in used.tolist()]
    first = np.fromiter((priority(r, manned_first)[0] for r in recs), dtype=np.intp, count=len(recs))
    rank = np.zeros(n, dtype=np.intp)
    rank[used[np.lexsort((np.array([r.id for r in recs]), first))]] = np.arange(len(recs))
    goes = np.zeros(n, dtype=bool)
    goes[used] = np.fromiter((right_of_way._goes(r, held) for r in recs), dtype=bool, count=len(recs))
    way = np.zeros((n, 2), dtype=float)
    way[used] = np.array([r.last_vector or (0.0, 0.0) for r in recs], dtype=float).reshape(-1, 2)
    k = at[i]
    behind = (along > AHEAD * gap) & ((way[j] * vec[k]).sum(axis=1) > FOLLOW)
    keep = (rank[j] < rank[i]) & goes[j] & ~behind & deadlocks.meet(rel, way[j] - vec[k], pair_s)
    k, j, gap = k[keep], j[keep], gap[keep]
    order = np.lexsort((np.arange(len(k)), gap, k))
    first_of = order[np.unique(k[order], return_index=True)[1]]
    best = np.full(len(moving), -1, dtype=np.intp)
    near = np.full(len(moving), np.inf)
    best[k[first_of]], near[k[first_of]] = j[first_of], gap[first_of]
    return best, near


@pytest.mark.parametrize("seed", [1, 2])
def test_right_of_ways_blockers_are_the_fleet_arrays(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(seed)
    w = World(WorldSettings(dispersion=DispersionSettings(enabled=True)))
    # 80 units in a 300 m x 2 km strip (vehicles keep 50 m), half of them manned, crossing it both ways
    at = {f"u{k:02d}": (rng.uniform(0, 300), rng.uniform(0, 2000)) for k in range(80)}
    w.apply(
        [
            StateReported(u, UnitState(position=p, seq=0, kind=UnitKind("manned" if k % 2 else "unmanned")))
            for k, (u, p) in enumerate(at.items())
        ],
        0.0,
    )
    w.apply(
        [
            GoalSet(u, Goal(position=(3000.0 - p[0] if k % 3 else p[0], p[1] + 500.0)))
            for k, (u, p) in enumerate(at.items())
        ],
        0.0,
    )
    compared, found = [0], [0]
    plain = right_of_way.blockers

    def both(*args: Any) -> tuple[np.ndarray, np.ndarray]:
        got = plain(*args)
        want = _blockers_over_the_fleet(*args)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        compared[0] += 1
        found[0] += int((got[0] >= 0).sum())
        return got

    monkeypatch.setattr(world_dispersion, "blockers", both)
    units = list(at)
    for t in range(1, 240):
        k = t % len(units)
        batch = units[k : k + 1 + t % 5]  # ticks of one to five reports
        for u in batch:
            d = w._units[u].last_vector or (0.0, 0.0)
            at[u] = (at[u][0] + 5.0 * d[0], at[u][1] + 5.0 * d[1])
        w.apply(
            [
                StateReported(
                    u,
                    UnitState(
                        position=at[u], seq=t, kind=UnitKind("manned" if units.index(u) % 2 else "unmanned")
                    ),
                )
                for u in batch
            ],
            0.5 * t,
        )
    assert compared[0] > 100 and found[0] > 10  # judged often, and some held for another


@pytest.mark.parametrize("seed", range(4))
def test_a_kept_trees_slack_from_its_moved_rows_is_the_slack_over_every_row(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 300
    points = rng.uniform(0.0, 2_000.0, size=(n, 2))
    seps = rng.choice([5.0, 50.0], n)
    team = rng.integers(-1, 20, n).astype(np.intp)
    team_sep = np.where(team >= 0, 60.0, math.nan)
    told = plain = NeighbourIndex(points, seps, team, team_sep)
    rebuilt = 0
    for _ in range(60):  # small moves and back, some past the share: the tree rebuilt now and then
        moved = sorted(set(rng.choice(n, size=int(rng.integers(0, 6))).tolist()))
        points = points.copy()
        points[moved] += rng.normal(0.0, 15.0, size=(len(moved), 2))
        told = NeighbourIndex(points, told.seps, told.team, told.team_sep, moved_from=told, moved=moved)
        plain = NeighbourIndex(points, plain.seps, plain.team, plain.team_sep, moved_from=plain)
        assert told._slack == plain._slack and told.radius == plain.radius
        assert np.array_equal(told._treed, plain._treed)
        rebuilt += told._slack == 0.0
        rows = np.array(moved or [0])
        assert _same(told.gradients(rows), plain.gradients(rows))
    assert 0 < rebuilt < 60


@pytest.mark.parametrize("seed", range(20))
def test_a_few_leads_one_route_at_a_time_are_the_batched_leads(seed: int) -> None:
    """``teams.leads`` asks up to ``_ONE_BY_ONE`` array routes one at a time (``polyline_kernels.place``):
    every verdict is the one the batched call (``places``, the routes as points) gives, to the bit."""
    rng = random.Random(seed)
    asks = []
    for k in range(rng.randint(1, roles._ONE_BY_ONE)):
        at = (rng.uniform(-500, 500), rng.uniform(-500, 500))
        route = [(rng.uniform(-500, 500), rng.uniform(-500, 500)) for _ in range(rng.choice([2, 3, 5, 18]))]
        if rng.random() < 0.3:
            route.insert(1, route[0])  # the walk's first point is where the main element stands
        asks.append((at, route, rng.choice([0.0, rng.uniform(0.0, 400.0)]), f"m{k}"))
    want = roles.leads(asks)  # points: the batched call
    got = roles.leads([(at, np.array(r, dtype=float).reshape(-1, 2), s, m) for at, r, s, m in asks])
    assert got == want
    for at, route, standoff, _ in asks:  # and the numbers a Polyline gives
        line = roles.Polyline(route)
        out = np.empty(4)
        polyline_kernels.place(np.array(route, dtype=float), at[0], at[1], standoff, out)
        assert out[0] == line.length
        if line.length > standoff:
            assert out[1] == line.project(at)[0] and tuple(out[2:].tolist()) == tuple(line.point_at(standoff))
