"""The one per-threat kernel: every compiled sum and the core test are made of ``threat_term``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import Threat, ThreatField, kernels
from pfp_service.core.cores import Cores

pytestmark = pytest.mark.unit

SHAPES = [
    ((0.0, 0.0), 0.0, 2.0, 1.0, 0.0, 1.0),
    ((3.0, 1.0), 70.0, 1.5, 0.7, 4.0, 0.6),
    ((-2.0, 4.0), 200.0, 3.0, 2.5, 1.2, 1.4),
]


def _terms(packed, x, y, grad):
    return np.array([kernels.threat_term(packed, j, x, y, 0.0, grad) for j in range(len(packed))])


def test_packed_columns_are_named_once_and_fill_the_rows():
    assert len(kernels.PACKED_COLUMNS) == len(set(kernels.PACKED_COLUMNS)) == kernels.VIS_DATA == 17
    for name in kernels.PACKED_COLUMNS:
        assert getattr(kernels, name.upper()) == kernels.PACKED_COLUMNS.index(name)
    t = Threat.from_facing(*SHAPES[1])
    row = ThreatField([t]).packed[0]
    assert (row[kernels.XI_X], row[kernels.XI_Y]) == t.xi
    assert tuple(row[[kernels.P00, kernels.P01, kernels.P11]]) == t.precision()
    assert tuple(row[[kernels.A_X, kernels.A_Y]]) == t.shape()
    assert row[kernels.ACTIVE] == 1.0


def test_field_sums_are_sums_of_the_per_threat_term():
    field = ThreatField([Threat.from_facing(*s) for s in SHAPES])
    for x, y in np.random.default_rng(4).uniform(-6, 8, (50, 2)):
        terms = _terms(field.packed, x, y, True)
        v, gx, gy = kernels.point_level_grad(field.packed, x, y)
        np.testing.assert_allclose((v, gx, gy), terms.sum(axis=0), rtol=1e-14, atol=1e-300)
        assert kernels.point_level(field.packed, x, y) == v
        assert np.array_equal(_terms(field.packed, x, y, False)[:, 0], terms[:, 0])


def test_inactive_rows_and_the_floor_give_exact_zeros():
    field = ThreatField([Threat.from_facing(*s) for s in SHAPES])
    packed = field.packed.copy()
    packed[1, kernels.ACTIVE] = 0.0
    assert kernels.threat_term(packed, 1, 3.0, 1.0, 0.0, True) == (0.0, 0.0, 0.0)
    alone = ThreatField([Threat.from_facing(SHAPES[0][0], *SHAPES[0][1:]), Threat.from_facing(*SHAPES[2])])
    assert kernels.point_level_grad(packed, 0.5, 0.5) == kernels.point_level_grad(alone.packed, 0.5, 0.5)
    v = kernels.threat_term(field.packed, 0, 0.0, 0.0, 0.0, False)[0]
    assert v > 0.0 and kernels.threat_term(field.packed, 0, 0.0, 0.0, 10.0 * v, False)[0] == 0.0


def test_cores_use_the_same_term_normalised_to_the_peak():
    threats = [Threat.from_facing(*s) for s in SHAPES]
    cores = Cores(ThreatField(threats))
    pts = np.random.default_rng(9).uniform(-6, 8, (200, 2))
    ratio, idx = cores.ratio(pts)
    for p, r, j in zip(pts, ratio, idx):
        per = _terms(cores.packed, p[0], p[1], False)[:, 0]
        assert r == per.max() and (j == int(np.argmax(per)) or r == 0.0)
    assert np.array_equal(cores.inside(pts), ratio >= cores.fraction)
    for t in threats:  # 1 at the threat's mode: the field's peak-intensity level over its weight
        one = Cores(ThreatField([t]))
        mode = _mode(t)
        assert abs(one.ratio(np.array([mode]))[0][0] - 1.0) < 1e-6


def _mode(t):
    from scipy.optimize import minimize

    f = ThreatField([Threat(t.xi, t.omega, t.alpha, 1.0)])
    return minimize(lambda p: -f.level(p[None, :])[0], np.array(t.xi), method="Nelder-Mead", tol=1e-12).x


def test_core_raster_is_the_core_test_on_a_lattice():
    rng = np.random.default_rng(5)
    threats = [
        Threat.from_facing(
            rng.uniform(0, 60, 2), rng.uniform(0, 360), rng.uniform(1, 4), rng.uniform(0.2, 3), k
        )
        for k in rng.uniform(0, 30, 25)
    ]
    cores = Cores(ThreatField(threats))
    h, shape = 0.3, (201, 181)
    nodes = np.stack(np.meshgrid(np.arange(shape[0]) * h, np.arange(shape[1]) * h, indexing="ij"), -1)
    assert np.array_equal(
        cores.raster((0.0, 0.0), h, shape), cores.inside(nodes.reshape(-1, 2)).reshape(shape)
    )


def test_level_raster_differs_from_the_field_only_by_the_floor():
    field = ThreatField([Threat.from_facing(*s) for s in SHAPES])
    h, shape = 0.1, (141, 121)
    out = np.zeros(shape)
    floor = 1e-12
    kernels.raster_level(field.packed, -6.0, -4.0, h, floor, out)
    nodes = np.stack(
        np.meshgrid(-6.0 + np.arange(shape[0]) * h, -4.0 + np.arange(shape[1]) * h, indexing="ij"), -1
    )
    exact = field.level(nodes)
    assert np.all(out <= exact * (1 + 1e-12) + 1e-300)
    assert np.max(exact - out) <= len(SHAPES) * floor


def test_culled_level_drops_only_terms_below_the_floor():
    from pfp_service.core.threat import LEVEL_FLOOR

    rng = np.random.default_rng(12)
    threats = [
        Threat.from_facing(
            rng.uniform(0, 1000, 2), rng.uniform(0, 360), s, s * rng.uniform(0.3, 1), rng.uniform(0, 3)
        )
        for s in rng.uniform(5, 20, 300)
    ]
    field = ThreatField(threats)
    pts = rng.uniform(-100, 1100, (30_000, 2))
    exact, culled = field.level(pts), field.level_culled(pts)
    assert np.all(culled <= exact * (1 + 1e-12) + 1e-300)
    assert np.max(exact - culled) <= len(threats) * LEVEL_FLOOR * float(field.packed[:, kernels.SCALE].max())
    assert np.array_equal(ThreatField().level_culled(pts[:3]), np.zeros(3))


def test_segment_hits_are_first_hit_per_segment():
    rng = np.random.default_rng(2)
    threats = [
        Threat.from_facing(
            rng.uniform(0, 50, 2), rng.uniform(0, 360), rng.uniform(1, 3), rng.uniform(0.2, 3), k
        )
        for k in rng.uniform(0, 40, 12)
    ]
    cores = Cores(ThreatField(threats))
    path = np.cumsum(rng.normal(0, 4, (80, 2)), axis=0) + 25.0
    hits = cores.segment_hits(path)
    assert hits.shape == (79,) and hits.any() and not hits.all()
    assert hits.tolist() == [bool(cores.first_hit(path[i : i + 2])) for i in range(79)]


# -- add_term's skip (a term too small to change a bit of a sum) against the plain sum of threat_term --
def _fleet(seed: int, masked: bool, box: float = 30_000.0, n: int = 400):
    """Threats spread as ``pfp bench engine``'s fleet case (most pairs far apart), some inactive, every
    third masked by a random window when ``masked``; and ``n`` points, some far outside the box, a few
    not finite or extreme."""
    from pfp_service.core.visibility import Window

    rng = np.random.default_rng(seed)
    sigmas = rng.uniform(200.0, 900.0, 60)
    threats = [
        Threat.from_facing(
            tuple(rng.uniform(0, box, 2)), rng.uniform(0, 360), s, s * rng.uniform(0.3, 1), 2.0
        )
        for s in sigmas
    ]
    windows = {j: rng.uniform(0.0, 4.0, (9, 11)) for j in range(0, len(threats), 3)} if masked else {}
    index = {id(t): j for j, t in enumerate(threats)}

    def sight(t, reach):
        low = windows.get(index[id(t)])
        cell = max(reach[2] - reach[0], reach[3] - reach[1]) / 8.0
        return None if low is None else Window(reach[0], reach[1], cell, low, 1.5, 0.25)

    packed = ThreatField(threats, sight=sight).packed.copy()
    packed[rng.choice(len(threats), 5, replace=False), kernels.ACTIVE] = 0.0
    odd = [(np.nan, 0.0), (np.inf, 5.0), (-np.inf, np.inf), (1e300, -1e300), (1e-300, 0.0), (0.0, -0.0)]
    pts = np.concatenate(
        [rng.uniform(0, box, (n - 20 - len(odd), 2)), rng.uniform(-3 * box, 4 * box, (20, 2)), odd]
    )
    return packed, pts, rng.uniform(0, box, (n, 2)), rng.uniform(1e-7, 1e-5, n)


def _summed_terms(packed, x, y, listed=None):
    """The general path: every ``threat_term`` added in order, as a plain Python float sum."""
    val = gx = gy = 0.0
    for j in range(len(packed)) if listed is None else listed:
        v, dx, dy = kernels.threat_term(packed, int(j), float(x), float(y), 0.0, True)
        val, gx, gy = val + v, gx + dx, gy + dy
    return val, gx, gy


@np.errstate(over="ignore")  # an extreme point's norm overflows to inf, in the kernel too
def _descent_rows(packed, pts, goals, gains, listed=lambda i: None):
    rows = []
    for i, (x, y) in enumerate(pts):
        val, gx, gy = _summed_terms(packed, x, y, listed(i))
        fx = gx - 2.0 * gains[i] * (goals[i, 0] - x)
        fy = gy - 2.0 * gains[i] * (goals[i, 1] - y)
        rows.append((fx, fy, val, np.sqrt(fx * fx + fy * fy)))
    return np.array(rows)


def _same_bits(a, b) -> bool:
    return np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))


@pytest.mark.parametrize("masked", [False, True])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_gradient_sums_skip_only_terms_that_change_no_bit(seed, masked):
    packed, pts, goals, gains = _fleet(seed, masked)
    assert (packed[:, kernels.VIS_NX] > 0).any() == masked
    want = _descent_rows(packed, pts, goals, gains)
    for name, kernel in (("batch", kernels.batch_descent), ("serial", kernels._serial_descent)):
        out = np.empty((len(pts), 4))
        kernel(packed, pts, goals, gains, out)
        assert _same_bits(out, want), f"seed {seed}, masked {masked}: {name} differs from the summed terms"
    for (x, y), row in zip(pts[:50], want[:50]):
        assert _same_bits(kernels.point_level_grad(packed, x, y), _summed_terms(packed, x, y)), (seed, x, y)
    # the inputs exercise the skip: many nonzero terms lie far below their sum's last place
    x, y = pts[0]
    terms = [kernels.threat_term(packed, j, x, y, 0.0, True)[0] for j in range(len(packed))]
    val = np.cumsum(terms)
    assert sum(0.0 < t < np.spacing(s) / 8 for t, s in zip(terms[1:], val[:-1])) >= 5, f"seed {seed}"


@pytest.mark.parametrize("masked", [False, True])
def test_culled_rows_are_the_summed_terms_of_their_cell(masked):
    from pfp_service.core import cull

    packed, pts, goals, gains = _fleet(4, masked, box=10_000.0)
    index = cull.CullIndex(packed)
    grid = (index.origin[0], index.origin[1], index.cell, index.nx, index.ny)

    def listed(i):
        x, y = (float(v) for v in pts[i])
        if not (math.isfinite(x) and math.isfinite(y)):
            return []
        ci = math.floor((x - index.origin[0]) / index.cell)
        ck = math.floor((y - index.origin[1]) / index.cell)
        if not (0 <= ci < index.nx and 0 <= ck < index.ny):
            return []
        c = ck * index.nx + ci
        return index.indices[index.indptr[c] : index.indptr[c + 1]]

    out, flags = np.empty((len(pts), 4)), np.zeros(len(pts), dtype=np.bool_)
    cull._culled_descent(
        packed, pts, goals, gains, grid, index.indptr, index.indices, index.cell_bound, 0.0, out, flags
    )
    assert _same_bits(out, _descent_rows(packed, pts, goals, gains, listed)), f"masked {masked}"
