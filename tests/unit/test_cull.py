"""Culling: only nearby threats are evaluated, and the direction stays within the proven bound."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pfp_service.core import Threat, ThreatField
from pfp_service.core.cull import RELATIVE_BOUND, CullIndex
from pfp_service.core.kernels import descent_many

pytestmark = pytest.mark.unit

MAX_ERROR_DEG = 0.1  # what the service promises; the proof gives asin(RELATIVE_BOUND)


def _field(seed: int, n: int, extent: float, intensity: str) -> ThreatField:
    rng = np.random.default_rng(seed)
    threats = []
    for j in range(n):
        s_r = float(rng.uniform(0.002, 0.01) * extent)
        threats.append(
            Threat.from_facing(
                (float(rng.uniform(0, extent)), float(rng.uniform(0, extent))),
                float(rng.uniform(0, 360)),
                s_r,
                float(s_r * rng.uniform(0.25, 4)),
                float(rng.uniform(0, 50)),
                float(rng.uniform(0.1, 5)),
                f"t{j}",
            )
        )
    return ThreatField(threats, intensity)  # type: ignore[arg-type]


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    dot = np.einsum("ij,ij->i", a, b)
    return np.degrees(np.abs(np.arctan2(cross, dot)))  # accurate near 0, where arccos is not


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(40, 400),
    extent=st.sampled_from([100.0, 5_000.0, 30_000.0]),
    intensity=st.sampled_from(["peak", "density"]),
)
def test_culled_directions_are_within_the_bound(seed, n, extent, intensity):
    print(f"seed={seed} n={n} extent={extent} intensity={intensity}")
    field = _field(seed, n, extent, intensity)
    rng = np.random.default_rng(seed + 1)
    m = 500
    pts = rng.uniform(-0.1 * extent, 1.1 * extent, (m, 2))
    goals = rng.uniform(0, extent, (m, 2))
    gains = np.full(m, 1.0 / extent**2)
    full = np.empty((m, 4))
    culled = np.empty((m, 4))
    descent_many(field.packed, pts, goals, gains, full)
    index = CullIndex(field.packed)
    index.descent(pts, goals, gains, culled)
    moving = full[:, 3] > 0
    err = _angles(full[moving, :2], culled[moving, :2])
    assert err.max(initial=0.0) <= MAX_ERROR_DEG
    # the proof's own bound, with room for the two sums' rounding
    assert err.max(initial=0.0) <= math.degrees(math.asin(RELATIVE_BOUND)) + 1e-6
    assert np.all(np.abs(full[:, 2] - culled[:, 2]) <= index.level_bound + 1e-12 * np.abs(full[:, 2]))


def test_culling_skips_far_threats_and_falls_back_where_the_bound_is_loose():
    field = _field(7, 1000, 20_000.0, "peak")
    index = CullIndex(field.packed)
    per_cell = np.diff(index.indptr)
    assert per_cell.mean() < 100  # each unit sees a few nearby threats, not all 1000
    # at its goal, far from every threat, the gradient all but vanishes: that unit is evaluated in full
    pts = np.array([[-60_000.0, -60_000.0], [500.0, 500.0]])
    goals = pts.copy()
    out = np.empty((2, 4))
    assert index.descent(pts, goals, np.ones(2), out) == 1
    ref = np.empty((2, 4))
    descent_many(field.packed, pts, goals, np.ones(2), ref)
    np.testing.assert_allclose(out, ref, rtol=1e-9, atol=1e-300)


def test_an_empty_or_inactive_field_culls_to_the_goal_term():
    field = ThreatField([], "peak")
    index = CullIndex(field.packed)
    out = np.empty((1, 4))
    index.descent(np.array([[0.0, 0.0]]), np.array([[3.0, 4.0]]), np.array([1.0]), out)
    np.testing.assert_allclose(out[0], [-6.0, -8.0, 0.0, 10.0])


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.sampled_from([0, 5, 40, 300]), culled=st.booleans())
def test_predict_is_descent_stepped_one_call_at_a_time(seed, n, culled):
    """The compiled look-ahead gives, bit for bit, the positions of stepping ``descent`` by hand.

    The reference below is the rule written out again on purpose (arrival,
    bounds, the gradient, the final approach onto the goal), so a change to
    ``steprule.judge`` that the look-ahead does not share shows here.
    """
    from pfp_service.core import steprule
    from pfp_service.core.cull import predict

    extent = 5000.0
    field = _field(seed, n, extent, "peak")
    index = CullIndex(field.packed) if culled and n else None
    rng = np.random.default_rng(seed)
    m, steps = 60, 6
    pts = rng.uniform(0, extent, (m, 2))
    pts[0] = (np.nan, 1.0)  # a position that is not finite stops at once
    goals = rng.uniform(0, extent, (m, 2))
    goals[1] = pts[1]  # already at its goal
    gains = rng.uniform(1e-8, 1e-5, m)
    step = rng.uniform(1.0, 200.0, m)
    tol = rng.uniform(0.5, 50.0, m)
    lo = np.full((m, 2), 500.0)
    hi = np.full((m, 2), extent - 500.0)
    pts[2] = (2500.0, 2500.0)
    goals[2] = pts[2] + (0.6 * step[2], 0.0)  # a final approach: the first step ends on the goal
    tol[2] = 0.1 * step[2]
    units = np.stack(
        [
            steprule.unit(
                tuple(goals[i]), gains[i], tol[i], step[i], (tuple(lo[i]), tuple(hi[i])), watch=False
            )
            for i in range(m)
        ]
    )
    trail, lengths = predict(field.packed, index, pts, units, steps)
    for i in range(m):
        track = [tuple(pts[i])]
        x, y = pts[i]
        for _ in range(steps):
            if math.hypot(goals[i, 0] - x, goals[i, 1] - y) <= tol[i]:
                break
            if not (lo[i, 0] <= x <= hi[i, 0] and lo[i, 1] <= y <= hi[i, 1]):
                break
            out = np.empty((1, 4))
            args = (np.array([[x, y]]), goals[i : i + 1], gains[i : i + 1], out)
            index.descent(*args) if index is not None else descent_many(field.packed, *args)
            norm = out[0, 3]
            if not (math.isfinite(norm) and norm > 0.0):
                break
            dist = math.hypot(goals[i, 0] - x, goals[i, 1] - y)
            if dist <= step[i]:  # the final approach ends on the goal
                x, y = goals[i]
            else:
                x, y = x + step[i] * (-out[0, 0] / norm), y + step[i] * (-out[0, 1] / norm)
            track.append((float(x), float(y)))
        got = [tuple(p) for p in trail[i, : lengths[i]].tolist()]
        assert len(got) == len(track), i
        np.testing.assert_array_equal(np.array(got), np.array(track))
    assert lengths[0] == 1 and lengths[1] == 1
    assert lengths[2] == 2 and tuple(trail[2, 1]) == tuple(goals[2])  # landed, then arrived
    assert lengths.max() == steps + 1  # most units walked every step
