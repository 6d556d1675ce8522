"""Path metrics against independent computations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pfp_service.core import Threat, ThreatField
from pfp_service.core.metrics import Epoch, measure, segment_clearance

pytestmark = pytest.mark.unit


def test_exposure_matches_adaptive_quadrature():
    field = ThreatField(
        [
            Threat.from_facing((5.0, 5.5), 200.0, 1.0, 0.7, 2.0),
            Threat.from_facing((2.0, 1.0), 10.0, 0.8, 0.8, 1.0),
        ]
    )
    path = np.array([(0.0, 0.0), (3.0, 1.5), (6.0, 4.0), (10.0, 10.0)])
    fine = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        for t in np.linspace(0, 1, 400)[1:]:
            fine.append(a + t * (b - a))
    fine = np.array(fine)
    m = measure(fine, [Epoch(0, len(fine) - 1, field)])
    exact = 0.0
    for a, b in zip(path[:-1], path[1:]):
        seg = np.hypot(*(b - a))
        exact += quad(
            lambda t: field.level(np.array([a + t * (b - a)]))[0] * seg, 0, 1, epsabs=1e-12, limit=200
        )[0]
    assert m.exposure == pytest.approx(exact, rel=1e-8)
    assert m.length == pytest.approx(sum(np.hypot(*(b - a)) for a, b in zip(path[:-1], path[1:])))


def test_clearance_uses_segments_not_just_vertices():
    path = np.array([(0.0, 0.0), (10.0, 0.0)])
    assert segment_clearance(path, np.array([(5.0, 2.0)])) == pytest.approx(2.0)
    assert segment_clearance(path, np.array([(-3.0, 4.0)])) == pytest.approx(5.0)
    assert segment_clearance(path, np.empty((0, 2))) == math.inf


def test_epochs_count_threats_from_appearance():
    t = Threat.from_facing((5.0, 1.0), 0.0, 1.0, 1.0, 0.0)
    path = np.column_stack([np.linspace(0, 10, 101), np.zeros(101)])
    empty, full = ThreatField([]), ThreatField([t])
    all_in = measure(path, [Epoch(0, 100, full)])
    half = measure(path, [Epoch(0, 50, empty), Epoch(50, 100, full)])
    assert 0 < half.exposure < all_in.exposure
    assert half.exposure == pytest.approx(all_in.exposure / 2, rel=1e-6)  # symmetric about x = 5
    assert half.min_clearance == pytest.approx(1.0)


def test_compiled_clearance_is_the_segment_distance():
    rng = np.random.default_rng(21)
    path = np.cumsum(rng.normal(0, 3, (60, 2)), axis=0)
    path[10] = path[9]  # a zero-length segment
    positions = rng.uniform(-40, 40, (35, 2))
    a, ab = path[:-1, None, :], (path[1:] - path[:-1])[:, None, :]
    ap = positions[None, :, :] - a
    denom = np.einsum("ijk,ijk->ij", ab, ab)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.where(denom > 0, np.einsum("ijk,ijk->ij", ap, ab) / denom, 0.0), 0.0, 1.0)
    ref = float(np.hypot(*(ap - t[..., None] * ab).transpose(2, 0, 1)).min())
    assert abs(segment_clearance(path, positions) - ref) <= 1e-12 * max(1.0, ref)
    assert segment_clearance(path, np.zeros((0, 2))) == math.inf
