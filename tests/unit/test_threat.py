"""The threat model: the mapping, the density, the exact gradient, far-field zeros."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm

from pfp_service.core import Threat, ThreatField
from pfp_service.core.threat import skew_normal_mode

pytestmark = pytest.mark.unit

SHAPES = [
    ((0.0, 0.0), 0.0, 1.0, 1.0, 0.0),
    ((4.0, 6.0), 225.0, 1.0, 0.7, 2.0),
    ((-3.0, 2.0), 90.0, 2.0, 0.5, 5.0),
    ((1.0, -1.0), 313.0, 0.6, 1.4, 1.0),
]


def _grid(t: Threat, n: int = 801, k: float = 9.0):
    s = max(t.omega[0][0], t.omega[1][1]) ** 0.5
    xs = np.linspace(t.xi[0] - k * s, t.xi[0] + k * s, n)
    ys = np.linspace(t.xi[1] - k * s, t.xi[1] + k * s, n)
    gx, gy = np.meshgrid(xs, ys)
    return gx, gy, (xs[1] - xs[0]) * (ys[1] - ys[0])


@pytest.mark.parametrize("shape", SHAPES)
def test_density_integrates_to_one(shape):
    t = Threat.from_facing(*shape)
    gx, gy, cell = _grid(t)
    level = ThreatField([t], "density").level(np.stack([gx, gy], -1))
    assert level.sum() * cell == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("shape", SHAPES)
def test_density_matches_scipy_formula(shape):
    t = Threat.from_facing(*shape)
    rng = np.random.default_rng(1)
    pts = np.array(t.xi) + rng.normal(0, 1.5, (50, 2))
    mvn = multivariate_normal(mean=t.xi, cov=np.array(t.omega))
    a = np.array(t.shape())
    expected = 2 * mvn.pdf(pts) * norm.cdf((pts - np.array(t.xi)) @ a)
    got = ThreatField([t], "density").level(pts)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("shape", SHAPES)
def test_gradient_agrees_with_central_differences(shape):
    t = Threat.from_facing(*shape)
    field = ThreatField([t, Threat.from_facing((2.0, 2.0), 40.0, 1.2, 0.9, 1.5, 0.7)], "density")
    rng = np.random.default_rng(2)
    pts = np.array(t.xi) + rng.normal(0, 1.0, (40, 2))
    _, grad = field.level_grad(pts)
    h = 1e-6
    for (x, y), g in zip(pts, grad):
        fx = (field.level_grad_at(x + h, y)[0] - field.level_grad_at(x - h, y)[0]) / (2 * h)
        fy = (field.level_grad_at(x, y + h)[0] - field.level_grad_at(x, y - h)[0]) / (2 * h)
        scale = max(abs(g[0]), abs(g[1]), 1e-12)
        assert abs(fx - g[0]) / scale < 1e-6
        assert abs(fy - g[1]) / scale < 1e-6


def test_point_and_batch_agree():
    field = ThreatField([Threat.from_facing(*s) for s in SHAPES])
    pts = np.random.default_rng(3).uniform(-5, 8, (100, 2))
    level, grad = field.level_grad(pts)
    for p, lv, g in zip(pts, level, grad):
        v, gx, gy = field.level_grad_at(*p)
        assert (v, gx, gy) == (lv, g[0], g[1])
    np.testing.assert_allclose(field.level(pts), level, rtol=1e-13, atol=1e-300)


def test_far_field_is_exactly_zero_never_nan():
    field = ThreatField([Threat.from_facing(*s) for s in SHAPES])
    far = np.array([[1e6, 1e6], [-1e8, 3.0], [50.0, -50.0], [0.0, 1e9]])
    level, grad = field.level_grad(far)
    assert np.all(level == 0.0) and np.all(grad == 0.0)
    # behind a strongly skewed threat the cdf underflows while the density does not
    t = Threat.from_facing((0.0, 0.0), 0.0, 1.0, 1.0, 1000.0)
    v, gx, gy = ThreatField([t]).level_grad_at(0.0, -30.0)
    assert all(math.isfinite(q) for q in (v, gx, gy))
    assert v == 0.0


def test_facing_mapping_is_compass():
    # facing east (90 deg): wide in front (east), steep behind (west)
    t = Threat.from_facing((0.0, 0.0), 90.0, 1.0, 1.0, 3.0)
    f = ThreatField([t], "density")
    east, west = f.level(np.array([[1.5, 0.0], [-1.5, 0.0]]))
    assert east > 10 * west
    # omega^-1 alpha = k d / sigma_range, exactly as specified
    t = Threat.from_facing((0.0, 0.0), 30.0, 2.0, 0.5, 4.0)
    a = t.shape()
    d = (math.sin(math.radians(30)), math.cos(math.radians(30)))
    assert a == pytest.approx((4 * d[0] / 2.0, 4 * d[1] / 2.0), rel=1e-12)
    # the range spread lies along the facing
    omega = np.array(t.omega)
    assert np.array(d) @ omega @ np.array(d) == pytest.approx(4.0)


def test_raw_form_equals_facing_form():
    t = Threat.from_facing((1.0, 2.0), 135.0, 1.5, 0.8, 2.5, 0.7)
    raw = Threat(t.xi, t.omega, t.alpha, t.weight)
    pts = np.random.default_rng(4).uniform(-3, 5, (30, 2))
    for mode in ("peak", "density"):
        np.testing.assert_array_equal(ThreatField([t], mode).level(pts), ThreatField([raw], mode).level(pts))


@pytest.mark.parametrize("shape", SHAPES)
def test_peak_intensity_peaks_at_the_weight(shape):
    t = Threat.from_facing(*shape[:5], weight=0.8)
    gx, gy, _ = _grid(t, n=1201, k=4.0)
    level = ThreatField([t], "peak").level(np.stack([gx, gy], -1))
    assert level.max() == pytest.approx(0.8, rel=1e-4)
    assert level.max() <= 0.8 * (1 + 1e-12)


def test_skew_normal_mode():
    assert skew_normal_mode(0.0) == 0.0
    for q in (0.5, 1.0, 3.0, 20.0):
        v = skew_normal_mode(q)
        # the mode maximises phi(v) Phi(q v)
        g = lambda u: norm.pdf(u) * norm.cdf(q * u)
        assert g(v) >= max(g(v - 1e-4), g(v + 1e-4))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"omega": ((1e-170, 0.0), (0.0, 1e-170))},
        {"omega": ((1.0, 2.0), (2.0, 1.0))},
        {"omega": ((1.0, 0.5), (0.4, 1.0))},
        {"omega": ((math.inf, 0.0), (0.0, 1.0))},
        {"omega": ((1.0, 0.0), (0.0, 1.0)), "alpha": (math.nan, 0.0)},
        {"omega": ((1.0, 0.0), (0.0, 1.0)), "weight": math.inf},
        {"omega": ((1.0, 0.0), (0.0, 1.0)), "weight": -1.0},
    ],
)
def test_threat_refuses_what_it_cannot_evaluate(kwargs):
    args = {"xi": (0.0, 0.0), "alpha": (0.0, 0.0), **kwargs}
    with pytest.raises(ValueError, match="threat"):
        Threat(**args)


def test_threat_from_tiny_sigma_raises_value_error_not_zero_division():
    with pytest.raises(ValueError, match="positive definite"):
        Threat.from_facing((0, 0), 0.0, 1e-170, 1e-170, 0.0)
