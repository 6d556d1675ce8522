"""The per-tick shortcuts of issue 33's teams cost give the very numbers of the plain computation.

A team's track is grown as a ``Polyline`` a few points at a time
(``Polyline.extended``) rather than made afresh per follower: every array must
equal the one made from all the points at once, bit for bit, or a verdict at
an edge could move.  ``NeighbourIndex.near_seps`` hands a tick's later callers
the separations of the first query's pairs: they must equal ``pair_seps`` of
the same pairs, and a row's neighbours found in an earlier share of a wave must be
a new query's.  Without terrain, a robot's or controller's step inside every
radio disc goes without sampling: its verdict must be the sampled one.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.world import teams as roles
from pfp_service.world.teams import Point, Polyline

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


@pytest.mark.parametrize("seed", range(10))
def test_a_row_s_neighbours_found_before_are_a_new_query_s(seed: int) -> None:
    """A wave's shares ask one kept index (``unasked``) for rows, some asked before: each answer must be
    the very arrays a new index gives for those rows, in its order."""
    rng = np.random.default_rng(seed)
    n = 400
    points = rng.uniform(0.0, 1500.0, (n, 2))
    seps = rng.choice([10.0, 25.0, 50.0], n)
    kept = NeighbourIndex(points, seps)
    asked: list[int] = []
    for _ in range(12):
        rows = rng.choice(n, int(rng.integers(1, 90)), replace=False)
        if asked and rng.random() < 0.7:  # a later share: partly rows an earlier one asked
            rows = np.concatenate([rows[: len(rows) // 2], rng.choice(asked, min(len(asked), 20))])
        asked += rows.tolist()
        fresh = NeighbourIndex(points, seps)
        for a, b in zip(kept.unasked().near_seps(rows), fresh.near_seps(rows)):
            assert a.dtype == b.dtype and np.array_equal(a, b), f"seed {seed}"
        assert np.array_equal(kept.gradients(rows), fresh.gradients(rows)), f"seed {seed}"


def _sampled(at: Point, to: Point, centres: list[Point], radio_range_m: float) -> float:
    """How much of the step keeps every link, sampled as ``teams._kept`` samples it without terrain."""
    spacing = max(radio_range_m / 16.0, 1.0)
    return roles._kept(
        at, to, lambda p: all(roles.in_link(c, p, radio_range_m) for c in centres), spacing, None
    )


@pytest.mark.parametrize("seed", range(20))
def test_a_step_inside_every_disc_is_the_sampled_verdict(seed: int) -> None:
    """Without terrain a step whose ends lie inside every radio disc goes without sampling
    (``teams._within``): ``link`` and ``control`` must say what sampling the step says, steps
    grazing the discs' edges included."""
    rng = random.Random(seed)
    for _ in range(400):
        r = rng.choice([50.0, 300.0, 1500.0])
        c = (rng.uniform(-5e3, 5e3), rng.uniform(-5e3, 5e3))

        def near_edge() -> Point:  # a point about the disc's edge: inside, on it, or just past it
            a, f = (
                rng.uniform(0.0, 2.0 * math.pi),
                rng.choice([rng.uniform(0.0, 1.0), 1.0, 1.0 - 1e-9, 1.0 + 1e-9]),
            )
            return (c[0] + r * f * math.cos(a), c[1] + r * f * math.sin(a))

        at, to = near_edge(), near_edge()
        if not roles.in_link(c, at, r):
            continue
        kept = _sampled(at, to, [c], r)
        v = roles.link(at, to, c, r, "c", "")
        assert (v == roles.GO) == (kept >= 1.0), f"seed {seed}: {at} -> {to}, {v}"
        robots = [("r1", c)] + ([("r2", q)] if roles.in_link(at, q := near_edge(), r) else [])
        got, _ = roles.control(at, to, robots, r)
        assert (got == roles.GO) == (_sampled(at, to, [p for _, p in robots], r) >= 1.0), f"seed {seed}"


@pytest.mark.parametrize("seed", range(20))
def test_rows_among_the_last_query_s_are_isin_s(seed: int) -> None:
    """A query's rows all among the last query's rows take its pairs (``dispersion._among``, a mask over the
    fleet): it must say what ``np.isin(rows, asked).all()`` says (both unique, as ``_near_rows`` keeps them)."""
    from pfp_service.core import dispersion

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    for _ in range(200):
        asked = np.unique(rng.choice(n, int(rng.integers(0, n + 1)), replace=True))
        rows = np.unique(rng.choice(n, int(rng.integers(0, n + 1)), replace=True))
        if len(asked) and rng.random() < 0.5:  # often a subset, the wave's later callers' case
            rows = np.unique(rng.choice(asked, int(rng.integers(0, len(asked) + 1))))
        want = bool(np.isin(rows, asked, assume_unique=True).all())
        assert dispersion._among(rows, asked, n) == want, f"seed {seed}: {rows} in {asked}"


@pytest.mark.parametrize("seed", range(20))
def test_a_member_s_run_is_the_longest_of_its_last_runs(seed: int) -> None:
    """``Trails.run`` hands back the longest run kept when the member last moved: it must be the maximum
    of its last ``_RUNS`` runs (the oldest ones dropped), as taken afresh from them."""
    from collections import deque

    from pfp_service.world import team_link

    rng = random.Random(seed)
    trails = team_link.Trails()
    was: dict[str, Point] = {}
    runs: dict[str, deque[float]] = {}
    for _ in range(300):
        u = rng.choice(["r1", "r2", "m1"])
        if rng.random() < 0.05:
            trails.forget({u})
            was.pop(u, None)
            runs.pop(u, None)
            continue
        at = was.get(u) if rng.random() < 0.2 else (rng.uniform(-50, 50), rng.uniform(-50, 50))
        at = at if at is not None else (0.0, 0.0)
        trails.moved(u, at)
        if u in was and was[u] is not at and math.dist(was[u], at) > 0.0:
            runs.setdefault(u, deque(maxlen=team_link._RUNS)).append(math.dist(was[u], at))
        was[u] = at
        for v in ("r1", "r2", "m1"):
            want = max(runs[v]) if runs.get(v) else None
            assert trails.run(v) == want, f"seed {seed}: {v}"


@pytest.mark.parametrize("seed", range(10))
def test_leads_on_route_arrays_are_leads_on_route_points(seed: int) -> None:
    """``team_leads.main_route`` hands ``teams.leads`` each route as an array, not points: every verdict
    must be the one its points give, to the bit (the places are the numbers ``to`` carries)."""
    rng = random.Random(seed)
    asks = []
    for k in range(rng.randint(1, 40)):
        at = (rng.uniform(-500, 500), rng.uniform(-500, 500))
        route = [
            (rng.uniform(-500, 500), rng.uniform(-500, 500)) for _ in range(rng.choice([0, 1, 2, 5, 18]))
        ]
        if route and rng.random() < 0.3:
            route.insert(1, route[0])  # the walk's first point is where the main element stands
        asks.append((at, route, rng.uniform(0.0, 400.0), f"m{k}"))
    want = roles.leads(asks)
    got = roles.leads([(at, np.array(r, dtype=float).reshape(-1, 2), s, m) for at, r, s, m in asks])
    assert got == want, f"seed {seed}"
    mixed = [
        (at, np.array(r, dtype=float).reshape(-1, 2) if k % 2 else r, s, m)
        for k, (at, r, s, m) in enumerate(asks)
    ]
    assert roles.leads(mixed) == want, f"seed {seed}"


def test_a_main_element_s_route_array_is_its_route_s_points() -> None:
    """``team_leads.main_route`` takes the ghost walk's array (``Stepper.route_ahead_points``): row for row
    it must be where the unit is, then ``route_ahead``'s points, then its goal, to the bit."""
    from pfp_service.world import team_leads
    from tests.routed_fleet import walk

    on_route = 0
    for w, ids, _pos in walk(40, 30):
        for u in ids:
            rec = w._units[u]
            assert rec.position is not None
            st = rec.stepper
            ahead = st.route_ahead(*rec.position, team_leads.ROUTE_STEPS) if st is not None else None
            want = [rec.position, *(ahead or []), *([rec.goal.position] if rec.goal is not None else [])]
            got = team_leads.main_route(rec)
            assert got.shape == (len(want), 2) and got.tolist() == [list(p) for p in want], u
            on_route += ahead is not None
    assert on_route > 300, on_route  # the layout keeps most units on routes
