"""The per-tick shortcuts of issue 33's teams cost give the very numbers of the plain computation.

A team's track is grown as a ``Polyline`` a few points at a time
(``Polyline.extended``) rather than made afresh per follower: every array must
equal the one made from all the points at once, bit for bit, or a verdict at
an edge could move.  ``NeighbourIndex.near_seps`` hands a tick's later callers
the separations of the first query's pairs: they must equal ``pair_seps`` of
the same pairs.
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.world.teams import Polyline

pytestmark = pytest.mark.unit


@pytest.mark.parametrize("seed", range(40))
def test_a_grown_polyline_is_the_whole_one(seed: int) -> None:
    rng = random.Random(seed)
    pts = [(rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3)) for _ in range(rng.randint(0, 60))]
    if pts and seed % 3 == 0:
        pts += [pts[-1], pts[-1]]  # a lead that reported twice in place: a segment of no length
    line, k = Polyline([]), 0
    while k < len(pts):
        m = rng.randint(1, 5)
        line, k = line.extended(pts[k : k + m]), k + m
    whole = Polyline(pts)
    for name in ("pts", "ab", "seg", "sq", "cum"):
        got, want = getattr(line, name), getattr(whole, name)
        assert got.shape == want.shape and np.array_equal(got, want), f"seed {seed}: {name}"
    if pts:
        at = (rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3))
        assert line.project(at) == whole.project(at), f"seed {seed}"


@pytest.mark.parametrize("seed", range(10))
def test_near_seps_are_the_pairs_separations(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 300
    points = rng.uniform(0.0, 800.0, (n, 2))
    team = np.where(rng.random(n) < 0.5, rng.integers(0, 40, n), -1).astype(np.intp)
    team_sep = np.where(team >= 0, 80.0, np.nan)
    goals = np.where(rng.random((n, 1)) < 0.7, rng.uniform(0.0, 800.0, (n, 2)), np.nan)
    index = NeighbourIndex(points, rng.choice([10.0, 25.0, 50.0], n), team, team_sep, goals)
    first = rng.choice(n, 60, replace=False)
    for rows in (first, first[:20], first[::7]):  # the tick's advised units, then some of them
        i, j, s = index.near_seps(rows)
        fi, fj = index.near(rows)
        assert np.array_equal(i, fi) and np.array_equal(j, fj), f"seed {seed}"
        assert np.array_equal(s, index.pair_seps(i, j)), f"seed {seed}"
