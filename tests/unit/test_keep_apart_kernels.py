"""The compiled cut gives the NumPy's numbers, bit for bit (issue 33, ``core.keep_apart_kernels``).

``keep_apart.cut`` was NumPy over a tick's pairs, some fifty calls on a dozen rows; it is one compiled
call now.  The NumPy it stands for is kept here (``_reference``, ``keep_apart``'s ``_entries``,
``_moving_with``, ``_nearest``, ``_ray`` and ``_along`` before the kernel, on arrays): each pair's
entry, each moving unit's nearest and the pairs held are the same floats, ``inf`` included, on
random crowds and on the edges (a neighbour on a disc's edge, inside it, grazing it, given way to or
not, moving with the unit or against it, no pairs at all).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import keep_apart_kernels as kernels
from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.wire import Direction, DirectionStatus
from pfp_service.world import keep_apart
from pfp_service.world.keep_apart import _GRAZE_M, _NONE, _RULE, GIVEN, INSIDE, KEEP, WITH

pytestmark = pytest.mark.unit

# --- the NumPy formulation (keep_apart before the kernel), on arrays --------------------------------


def _entries(points, i, j, pair_s, vec, gives_way):
    rel = points[j] - points[i]
    along = (rel * vec).sum(axis=1)
    keep_m = KEEP * pair_s
    if gives_way is not None:
        keep_m = np.where(gives_way[j] == i, GIVEN * pair_s, keep_m)
    gap2 = (rel * rel).sum(axis=1)
    within = np.sqrt(gap2) <= keep_m + _GRAZE_M
    keep_m = np.where(within, np.minimum(keep_m, INSIDE * pair_s), keep_m)
    across2 = gap2 - along * along
    hit = (along > _GRAZE_M) & (across2 < keep_m * keep_m)
    enter = np.full(len(rel), np.inf)
    enter[hit] = np.maximum(along[hit] - np.sqrt(np.maximum(keep_m[hit] ** 2 - across2[hit], 0.0)), 0.0)
    return enter


def _moving_with(points, own, told, at, i, j, pair_s, vec, enter):
    if not len(i):
        return
    m = at[j]
    mm = np.maximum(m, 0)
    n = at[i]
    pick = np.flatnonzero((m >= 0) & own[mm] & own[n] & ((vec[mm] * vec[n]).sum(axis=1) > WITH))
    if not len(pick):
        return
    cap = np.minimum(told, _nearest(enter, n, len(own)))[m[pick]]
    rel = points[j[pick]] - points[i[pick]]
    s = pair_s[pick]
    keep = np.where(np.hypot(rel[:, 0], rel[:, 1]) <= KEEP * s + _GRAZE_M, GIVEN * s, KEEP * s)
    v, w = vec[n[pick]], vec[mm[pick]]
    moving = np.minimum(_along(rel, v, w, cap, keep), _ray(rel, v, GIVEN * s))
    enter[pick] = np.maximum(enter[pick], moving)


def _nearest(enter, n, count):
    hit = np.isfinite(enter)
    safe = np.full(count, np.inf)
    np.minimum.at(safe, n[hit], enter[hit])
    return safe


def _ray(rel, u, keep):
    a = (u * u).sum(axis=1)
    b = (rel * u).sum(axis=1)
    c = (rel * rel).sum(axis=1) - keep * keep
    disc = b * b - a * c
    hit = (b > _GRAZE_M) & (disc > 0.0) & (a > 0.0)
    out = np.full(len(rel), np.inf)
    out[hit] = np.maximum((b[hit] - np.sqrt(disc[hit])) / a[hit], 0.0)
    return out


def _along(rel, v, w, cap, keep):
    first = _ray(rel, v - w, keep)
    rest = cap + _ray(rel - cap[:, None] * (v - w), v, keep)
    return np.where(first <= cap, first, rest)


def _reference(points, rows, i, j, pair_s, vec, own, told, gives_way):
    """``keep_apart.cut``'s numbers as NumPy: each pair's entry, each unit's nearest, the pairs held."""
    at = np.full(len(points), -1, dtype=np.intp)
    at[rows] = np.arange(len(rows))
    n = at[i]
    enter = _entries(points, i, j, pair_s, vec[n], gives_way)
    _moving_with(points, own, told, at, i, j, pair_s, vec, enter)
    safe = _nearest(enter, n, len(rows))
    held = (enter <= _GRAZE_M) & (safe[n] <= _GRAZE_M)
    return enter, safe, list(zip(n[held].tolist(), j[held].tolist(), strict=True))


# --- the cases ---------------------------------------------------------------------------------------


def _compiled(points, rows, i, j, pair_s, vec, own, told, gives_way):
    ways = np.column_stack([vec, own.astype(float), told]).reshape(-1, 4)
    enter = np.empty(len(i))
    safe, held = kernels.cut(
        points, rows, i, j, pair_s, ways, _NONE if gives_way is None else gives_way, _RULE, enter
    )
    return enter, safe, [tuple(p) for p in held.tolist()]


def _pairs(points: np.ndarray, rows: np.ndarray, seps: np.ndarray):
    """Every other unit within 4 separations of each of ``rows`` (as ``near_seps`` gives them: by row)."""
    i, j = [], []
    for a in np.unique(rows).tolist():
        for b in range(len(points)):
            if b != a and math.hypot(*(points[b] - points[a])) <= 4.0 * max(seps[a], seps[b]):
                i.append(a)
                j.append(b)
    i_, j_ = np.array(i, dtype=np.intp), np.array(j, dtype=np.intp)
    return i_, j_, np.maximum(seps[i_], seps[j_])


def _case(seed: int):
    """A crowd: on a lattice of 3-4-5 steps (exact gaps on the discs' edges) or anywhere; ways along the
    axes, 3-4-5 or anywhere, some not unit; some on their own way, some told a reach, some giving way."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 40))
    seps = rng.choice([5.0, 20.0, 50.0], n)
    if seed % 2:
        points = rng.integers(-12, 12, (n, 2)) * rng.choice([5.5, 11.0, 2.5])
    else:
        points = rng.uniform(-150.0, 150.0, (n, 2))
    points = np.ascontiguousarray(points, dtype=float)
    rows = np.sort(rng.choice(n, size=int(rng.integers(1, n + 1)), replace=False)).astype(np.intp)
    ways = np.array([(0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0), (0.6, 0.8), (-0.8, 0.6)])
    vec = ways[rng.integers(0, len(ways), len(rows))]
    loose = rng.random(len(rows)) < 0.4
    angle = rng.uniform(0.0, 2.0 * math.pi, len(rows))
    vec[loose] = np.column_stack([np.sin(angle), np.cos(angle)])[loose] * rng.choice([1.0, 0.5, 3.0])
    own = rng.random(len(rows)) < 0.7
    told = rng.choice([0.0, 5.0, 25.0, 1e9], len(rows)) * (rng.random(len(rows)) < 0.8)
    i, j, pair_s = _pairs(points, rows, seps)
    gives_way = None
    if seed % 3 and len(i):
        gives_way = np.full(n, -1, dtype=np.intp)
        some = rng.random(len(i)) < 0.3
        gives_way[j[some]] = i[some]
    return points, rows, i, j, pair_s, np.ascontiguousarray(vec), own, told, gives_way


def _edges():
    """Pairs set on the edges: a neighbour on the disc's edge (55 m: 1.1 x 50, 33-44-55), just inside
    and outside it, inside the margin's inner half, dead ahead, grazing the disc's side, behind; going
    with the unit (north, 60 degrees off, just past 60) or against it; given way to or not."""
    s = 50.0
    keep = KEEP * s
    spots = [
        (33.0, 44.0),
        (0.0, keep),
        (0.0, keep + 2e-6),
        (0.0, keep - 1e-7),
        (0.0, INSIDE * s),
        (keep, 1e-6),  # grazing: the disc's side, barely ahead
        (keep, 10.0),
        (keep - 1e-9, 30.0),
        (0.0, -40.0),
        (30.0, 30.0),
        (0.0, 0.0),  # on the unit itself
    ]
    cases = []
    for way in [(0.0, 1.0), (0.6, 0.8), (1.0, 0.0)]:
        for with_ in [
            (0.0, 1.0),
            (math.sin(math.pi / 3), 0.5),
            (0.8660254037844386, 0.50000001),
            (0.0, -1.0),
        ]:
            for gives in (None, "all", "some"):
                points = np.array([(0.0, 0.0), *spots], dtype=float)
                rows = np.arange(len(points), dtype=np.intp)
                vec = np.array([way] + [with_] * len(spots), dtype=float)
                own = np.ones(len(points), dtype=bool)
                told = np.full(len(points), 5.0)
                i = np.zeros(len(spots), dtype=np.intp)
                j = np.arange(1, len(points), dtype=np.intp)
                gives_way = None
                if gives is not None:
                    gives_way = np.full(len(points), -1, dtype=np.intp)
                    gives_way[j if gives == "all" else j[::2]] = 0
                cases.append((points, rows, i, j, np.full(len(i), s), vec, own, told, gives_way))
    return cases


def _same(got, want) -> None:
    enter, safe, held = got
    r_enter, r_safe, r_held = want
    assert enter.shape == r_enter.shape and np.array_equal(enter, r_enter), (enter, r_enter)
    assert safe.shape == r_safe.shape and np.array_equal(safe, r_safe), (safe, r_safe)
    assert held == r_held


@pytest.mark.parametrize("seed", range(60))
def test_the_compiled_cut_is_the_numpys_on_random_crowds(seed: int) -> None:
    case = _case(seed)
    _same(_compiled(*case), _reference(*case))


def test_the_compiled_cut_is_the_numpys_on_the_edges() -> None:
    held = finite = 0
    for case in _edges():
        want = _reference(*case)
        _same(_compiled(*case), want)
        held += len(want[2])
        finite += int(np.isfinite(want[0]).sum())
    assert held and finite  # the edges do hold and do cut


def test_the_random_crowds_reach_every_branch() -> None:
    """The crowds above cut, hold, and lengthen entries for a neighbour going the unit's way."""
    cut = held = moved = 0
    for seed in range(60):
        points, rows, i, j, pair_s, vec, own, told, gives_way = _case(seed)
        enter, _, pairs = _reference(points, rows, i, j, pair_s, vec, own, told, gives_way)
        at = np.full(len(points), -1, dtype=np.intp)
        at[rows] = np.arange(len(rows))
        standing = _entries(points, i, j, pair_s, vec[at[i]], gives_way)
        cut += int(np.isfinite(enter).sum())
        held += len(pairs)
        moved += int((enter != standing).sum())
    assert cut > 1000 and held > 100 and moved > 50, (cut, held, moved)


def test_no_pairs() -> None:
    points = np.array([(0.0, 0.0), (500.0, 0.0)])
    none = np.zeros(0, dtype=np.intp)
    case = (points, np.array([0, 1], dtype=np.intp), none, none, np.zeros(0), np.eye(2), np.ones(2, bool))
    enter, safe, held = _compiled(*case, np.full(2, 5.0), None)
    assert len(enter) == 0 and held == [] and np.array_equal(safe, [np.inf, np.inf])
    _same((enter, safe, held), _reference(*case, np.full(2, 5.0), None))


@pytest.mark.parametrize("seed", range(10))
def test_entries_are_the_numpys(seed: int) -> None:
    """``free_way``'s entries (``kernels.entries``, a vector per pair) with and without a unit giving way."""
    points, _, i, j, pair_s, vec, _, _, gives_way = _case(seed)
    rng = np.random.default_rng(seed)
    per_pair = np.ascontiguousarray(vec[rng.integers(0, len(vec), len(i))]).reshape(-1, 2)
    for gives in (gives_way, None):
        out = np.empty(len(i))
        kernels.entries(points, i, j, pair_s, per_pair, _NONE if gives is None else gives, _RULE, out)
        assert np.array_equal(out, _entries(points, i, j, pair_s, per_pair, gives))


@pytest.mark.parametrize("seed", range(10))
def test_keep_apart_cut_sets_the_reaches_the_numpy_finds(seed: int) -> None:
    """Through ``keep_apart.cut`` on a real index: each reach is the least of the told one and the
    NumPy's nearest entry, and the stopped pairs are the NumPy's held ones."""
    rng = np.random.default_rng(seed)
    n = 30
    points = rng.uniform(-120.0, 120.0, (n, 2))
    index = NeighbourIndex(points, np.full(n, 20.0))
    statuses = [DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING, DirectionStatus.YIELDING]
    dirs = []
    for u in range(n):
        a = float(rng.uniform(0.0, 360.0))
        reach = [None, 5.0, 0.0][u % 3]
        way = (math.sin(math.radians(a)), math.cos(math.radians(a)))
        dirs.append(Direction(unit=f"u{u}", status=statuses[u % 3], vector=way, heading_deg=a, reach_m=reach))
    go = [int(k) for k in np.sort(rng.choice(n, size=20, replace=False))]
    rows = np.array(go, dtype=np.intp)
    gives_way = None
    if seed % 2:
        gives_way = np.full(n, -1, dtype=np.intp)
        gives_way[go[0]] = go[1]
    i, j, pair_s = index.near_seps(rows)
    vec = np.array([dirs[k].vector for k in go])
    own = np.array([dirs[k].status in keep_apart._OWN for k in go])
    told = np.array([dirs[k].reach_m or 0.0 for k in go])
    _, safe, held = _reference(index.points, rows, i, j, pair_s, vec, own, told, gives_way)
    before = list(dirs)
    stopped = keep_apart.cut(index, rows, dirs, go, gives_way)
    assert stopped == [(go[m], jj) for m, jj in held]
    for m, k in enumerate(go):
        r = before[k].reach_m
        want = r if not math.isfinite(safe[m]) or (r is not None and r <= safe[m]) else float(safe[m])
        assert dirs[k].reach_m == want
