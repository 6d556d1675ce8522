"""Invariants of the planner, checked with hypothesis (derandomised: a failure is reproducible)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pfp_service.core import PlannerParams, PlanStatus, Scheduled, Threat, plan

pytestmark = pytest.mark.unit

SETTINGS = settings(
    max_examples=30,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)

coord = st.floats(-8.0, 18.0)
threat_st = st.builds(
    lambda x, y, b, sr, sl, k, w: Threat.from_facing((x, y), b, sr, sl, k, w),
    coord,
    coord,
    st.floats(0, 360),
    st.floats(0.4, 2.5),
    st.floats(0.4, 2.5),
    st.floats(0, 5),
    st.floats(0.1, 2),
)
world_st = st.tuples(
    st.tuples(st.floats(-2, 2), st.floats(-2, 2)),
    st.tuples(st.floats(8, 12), st.floats(8, 12)),
    st.lists(threat_st, min_size=0, max_size=5),
)


def _run(start, goal, threats, **kw):
    # plain descent: the escapes search grids, which are only equivariant up to their resolution
    kw.setdefault("escape", "none")
    return plan(start, goal, [Scheduled(t) for t in threats], PlannerParams(**kw))


def _transform(threat: Threat, f, rot_deg: float, scale: float) -> Threat:
    c, s = math.cos(math.radians(rot_deg)), math.sin(math.radians(rot_deg))
    r = np.array([[c, -s], [s, c]])
    omega = scale**2 * r @ np.array(threat.omega) @ r.T
    # alpha transforms with omega's square roots: keep a = omega^-1 alpha rotating as a vector / scale
    a = r @ np.array(threat.shape()) / scale
    w = np.sqrt(np.diag(omega))
    return Threat(
        tuple(f(threat.xi)),
        ((omega[0, 0], omega[0, 1]), (omega[1, 0], omega[1, 1])),
        tuple(a * w),
        threat.weight,
    )


TOL = 1e-4  # relative to the start-goal distance: rounding grows along a path, a wrong transform is O(1)


def _same_path(got, want: np.ndarray, base) -> None:
    """``got`` follows ``want`` (``base`` transformed).  The trap verdict compares a
    net displacement with a threshold, so its exact step may move by rounding."""
    assert got.status is base.status
    d0 = np.hypot(*(want[-1] - want[0])) or 1.0
    if base.status.value == "trapped":
        assert abs(got.steps - base.steps) <= 20  # the default trap window
        n = min(got.steps, base.steps) - 20
        if n > 0:
            assert np.abs(np.array(got.path)[:n] - want[:n]).max() < TOL * d0
        return
    assert got.steps == base.steps
    assert np.abs(np.array(got.path) - want).max() < TOL * d0


def _well_conditioned(start, goal, threats, base) -> bool:
    """Whether ``base`` survives a nudge of its start by 1e-9 of the distance.

    Plain descent that grazes a saddle is chaotic: rounding at 1e-16 grows
    along the path until the track (or the step that ends it) differs.  No
    transform is exact in floating point, so equivariance is only asked of
    paths that a far larger nudge leaves where they were.
    """
    d0 = math.hypot(goal[0] - start[0], goal[1] - start[1]) or 1.0
    nudged = _run((start[0] + 1e-9 * d0, start[1] - 1e-9 * d0), goal, threats)
    if nudged.status is not base.status or abs(nudged.steps - base.steps) > (
        20 if base.status.value == "trapped" else 0
    ):
        return False
    n = min(len(nudged.path), len(base.path))
    return bool(np.abs(np.array(nudged.path[:n]) - np.array(base.path[:n])).max() < 0.1 * TOL * d0) and (
        math.isclose(nudged.exposure, base.exposure, rel_tol=1e-5, abs_tol=1e-10)
    )


@SETTINGS
@given(world_st, st.floats(-1e4, 1e4), st.floats(-1e4, 1e4))
def test_translation_equivariance(world, dx, dy):
    start, goal, threats = world
    base = _run(start, goal, threats)
    assume(_well_conditioned(start, goal, threats, base))
    f = lambda p: (p[0] + dx, p[1] + dy)
    moved = _run(f(start), f(goal), [t.translated(dx, dy) for t in threats])
    _same_path(moved, np.array(base.path) + [dx, dy], base)
    if moved.steps == base.steps:
        assert math.isclose(moved.exposure, base.exposure, rel_tol=1e-4, abs_tol=1e-9)


@SETTINGS
@given(world_st, st.floats(0, 360))
def test_rotation_equivariance(world, rot):
    start, goal, threats = world
    c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
    f = lambda p: (c * p[0] - s * p[1], s * p[0] + c * p[1])
    base = _run(start, goal, threats)
    assume(_well_conditioned(start, goal, threats, base))
    turned = _run(f(start), f(goal), [_transform(t, f, rot, 1.0) for t in threats])
    _same_path(turned, np.array([f(p) for p in base.path]), base)
    if turned.steps == base.steps:
        assert math.isclose(turned.exposure, base.exposure, rel_tol=1e-4, abs_tol=1e-9)


@SETTINGS
@given(world_st, st.floats(1e-2, 3e3))
def test_uniform_scaling_equivariance(world, k):
    start, goal, threats = world
    f = lambda p: (k * p[0], k * p[1])
    base = _run(start, goal, threats)
    assume(_well_conditioned(start, goal, threats, base))
    big = _run(f(start), f(goal), [_transform(t, f, 0.0, k) for t in threats])
    _same_path(big, np.array(base.path) * k, base)
    if big.steps == base.steps:
        # peak intensity: levels are scale-free, so exposure scales with length
        assert math.isclose(big.exposure, k * base.exposure, rel_tol=1e-4, abs_tol=1e-9 * k)
        assert math.isclose(big.peak_threat, base.peak_threat, rel_tol=1e-4, abs_tol=1e-9)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    world_st,
    st.sampled_from(["peak", "density"]),
    st.one_of(st.none(), st.floats(1e-3, 50)),
    st.sampled_from(["none", "auto"]),
)
def test_every_plan_terminates_honestly(world, intensity, delta, escape):
    start, goal, threats = world
    r = _run(start, goal, threats, intensity=intensity, delta=delta, escape=escape)
    assert r.steps <= r.params.max_iter
    assert len(r.path) == r.steps + 1
    assert r.exposure >= 0.0
    assert r.peak_threat >= 0.0
    last = r.path[-1]
    assert math.isclose(r.final_distance, math.hypot(goal[0] - last[0], goal[1] - last[1]))
    if r.status is PlanStatus.REACHED:
        assert r.final_distance <= r.params.tolerance
    else:
        assert r.final_distance > r.params.tolerance
        assert r.reason
