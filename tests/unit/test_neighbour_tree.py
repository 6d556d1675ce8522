"""The neighbour index keeps its k-d tree while a few units move (``NeighbourIndex(moved_from=...)``): the same
neighbours, pairs and gradients as an index built afresh on the same points, and a fresh tree once any unit is
further than ``STALE_SHARE`` of the reach from where the tree holds it."""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.core import dispersion
from pfp_service.core.dispersion import STALE_SHARE, NeighbourIndex

pytestmark = pytest.mark.unit

N, SEP = 400, 50.0


def _fresh_and_kept(rng, points, moved_by):
    seps = np.full(len(points), SEP)
    first = NeighbourIndex(points, seps)
    moved = points.copy()
    rows = rng.choice(len(points), size=20, replace=False)
    moved[rows] += rng.uniform(-moved_by, moved_by, size=(len(rows), 2))
    return NeighbourIndex(moved, seps), NeighbourIndex(moved, seps, moved_from=first), first


@pytest.mark.parametrize("seed", range(6))
def test_a_kept_tree_finds_what_a_fresh_one_does(seed):
    rng = np.random.default_rng(seed)
    points = rng.uniform(0.0, 2_000.0, size=(N, 2))
    fresh, kept, first = _fresh_and_kept(rng, points, 0.1 * 2.0 * SEP)
    assert kept.tree is first.tree and fresh.tree is not first.tree  # kept, with some slack
    rows = rng.choice(N, size=16, replace=False)
    for a, b in zip(fresh.near(rows), kept.near(rows), strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(fresh.gradients(rows), kept.gradients(rows))
    for a, b in zip(fresh.pairs(), kept.pairs(), strict=True):
        assert np.array_equal(a, b)


def test_units_at_exactly_the_reach_count_alike():
    reach = dispersion.REACH * SEP  # 100 m: (60, 80) is exactly on it
    points = np.array([[0.0, 0.0], [60.0, 80.0], [200.0, 0.0], [260.0, 80.0], [500.0, 500.0]])
    seps = np.full(len(points), SEP)
    first = NeighbourIndex(points + [[0.0, 0.0], [0.0, 0.0], [-3.0, 0.0], [0.0, 0.0], [0.0, 0.0]], seps)
    kept, fresh = NeighbourIndex(points, seps, moved_from=first), NeighbourIndex(points, seps)
    assert kept.tree is first.tree and kept.radius == reach
    rows = np.arange(len(points))
    for a, b in zip(fresh.near(rows[:1]), kept.near(rows[:1]), strict=True):
        assert np.array_equal(a, b)
    assert kept.near(np.array([2]))[1].tolist() == fresh.near(np.array([2]))[1].tolist() == [3]


def test_a_unit_moved_past_the_share_builds_a_fresh_tree():
    rng = np.random.default_rng(9)
    points = rng.uniform(0.0, 2_000.0, size=(N, 2))
    seps = np.full(N, SEP)
    first = NeighbourIndex(points, seps)
    far = points.copy()
    far[7] += (STALE_SHARE * dispersion.REACH * SEP + 1.0, 0.0)
    assert NeighbourIndex(far, seps, moved_from=first).tree is not first.tree
    near = points.copy()
    near[7] += (STALE_SHARE * dispersion.REACH * SEP - 1.0, 0.0)
    assert NeighbourIndex(near, seps, moved_from=first).tree is first.tree


def test_a_unit_moved_into_reach_is_found_and_one_moved_out_is_not():
    far = [(5_000.0 + 300.0 * k, 5_000.0) for k in range(10)]  # enough units that one row is queried alone
    before = np.array([(0.0, 0.0), (110.0, 0.0), (0.0, 95.0), *far])  # the reach is 100 m
    after = np.array([(0.0, 0.0), (95.0, 0.0), (0.0, 110.0), *far])
    seps = np.full(len(after), SEP)
    kept = NeighbourIndex(after, seps, moved_from=NeighbourIndex(before, seps))
    assert kept.tree is not None and kept._slack == 15.0
    got = kept.near(np.array([0]))[1].tolist()
    assert got == NeighbourIndex(after, seps).near(np.array([0]))[1].tolist() == [1]
