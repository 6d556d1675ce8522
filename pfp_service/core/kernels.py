"""Compiled inner loops: the threat field's value and closed-form gradient.

Everything here is a pure function of arrays and floats, compiled with numba.
A threat set travels as one packed ``(M, 9)`` float64 array (see
``threat.PACKED_COLUMNS``), so a call unboxes one array instead of nine.

The gradient is exact:  with ``z = x - xi``, ``P = Omega^-1``, ``a = omega^-1 alpha``
and ``u = a.z``,  ``grad t = 2 phi2(z; Omega) (phi(u) a - Phi(u) P z)``.
A pair whose Mahalanobis term exceeds ``Q_CUTOFF`` is skipped: there
``exp(-q/2)`` underflows to exactly 0.0, so skipping changes no bit of the
result and keeps far-away threats free (and never NaN).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "Q_CUTOFF",
    "batch_descent",
    "batch_level",
    "batch_level_grad",
    "point_descent",
    "point_level_grad",
]

# exp(-x) == 0.0 in float64 for x > 745.14; 2 * 746 leaves a margin.
Q_CUTOFF = 1492.0
_INV_SQRT2 = 1.0 / math.sqrt(2.0)
_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)

# Packed columns: xi_x, xi_y, P00, P01, P11, a_x, a_y, coef, (reserved: active 1/0)
_XX, _XY, _P00, _P01, _P11, _AX, _AY, _COEF, _ACTIVE = range(9)

_jit = numba.njit(cache=True, fastmath=False, nogil=True)


@_jit
def point_level_grad(packed: np.ndarray, x: float, y: float) -> tuple[float, float, float]:
    """Weighted threat level and its gradient at one point."""
    val = 0.0
    gx = 0.0
    gy = 0.0
    for j in range(packed.shape[0]):
        if packed[j, _ACTIVE] == 0.0:
            continue
        zx = x - packed[j, _XX]
        zy = y - packed[j, _XY]
        p00 = packed[j, _P00]
        p01 = packed[j, _P01]
        p11 = packed[j, _P11]
        pzx = p00 * zx + p01 * zy
        pzy = p01 * zx + p11 * zy
        q = zx * pzx + zy * pzy
        if q > Q_CUTOFF:
            continue
        e = packed[j, _COEF] * math.exp(-0.5 * q)
        ax = packed[j, _AX]
        ay = packed[j, _AY]
        u = ax * zx + ay * zy
        cdf = 0.5 * math.erfc(-u * _INV_SQRT2)
        pdf = _INV_SQRT2PI * math.exp(-0.5 * u * u)
        val += e * cdf
        gx += e * (pdf * ax - cdf * pzx)
        gy += e * (pdf * ay - cdf * pzy)
    return val, gx, gy


@_jit
def point_descent(
    packed: np.ndarray, x: float, y: float, goal_x: float, goal_y: float, goal_gain: float
) -> tuple[float, float, float, float]:
    """Gradient of the full potential at one point.

    ``goal_gain`` is ``delta / ||goal - x0||^2``, so the goal term's gradient is
    ``-2 goal_gain (goal - x)``.

    Returns:
        ``(grad_x, grad_y, level, grad_norm)`` of ``f`` at ``(x, y)``.
    """
    level, gx, gy = point_level_grad(packed, x, y)
    fx = gx - 2.0 * goal_gain * (goal_x - x)
    fy = gy - 2.0 * goal_gain * (goal_y - y)
    return fx, fy, level, math.sqrt(fx * fx + fy * fy)


@numba.njit(cache=True, parallel=True, nogil=True)
def batch_level_grad(packed: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
    """Level and gradient at many points: ``out[i] = (level, gx, gy)``."""
    for i in numba.prange(points.shape[0]):
        v, gx, gy = point_level_grad(packed, points[i, 0], points[i, 1])
        out[i, 0] = v
        out[i, 1] = gx
        out[i, 2] = gy


@numba.njit(cache=True, parallel=True, nogil=True)
def batch_level(packed: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
    """Level only at many points (no gradient): contour plots and exposure."""
    for i in numba.prange(points.shape[0]):
        x = points[i, 0]
        y = points[i, 1]
        val = 0.0
        for j in range(packed.shape[0]):
            if packed[j, _ACTIVE] == 0.0:
                continue
            zx = x - packed[j, _XX]
            zy = y - packed[j, _XY]
            q = packed[j, _P00] * zx * zx + 2.0 * packed[j, _P01] * zx * zy + packed[j, _P11] * zy * zy
            if q > Q_CUTOFF:
                continue
            u = packed[j, _AX] * zx + packed[j, _AY] * zy
            val += packed[j, _COEF] * math.exp(-0.5 * q) * 0.5 * math.erfc(-u * _INV_SQRT2)
        out[i] = val


@_jit
def _descent_row(
    packed: np.ndarray, points: np.ndarray, goals: np.ndarray, gains: np.ndarray, out: np.ndarray, i: int
) -> None:
    fx, fy, level, norm = point_descent(
        packed, points[i, 0], points[i, 1], goals[i, 0], goals[i, 1], gains[i]
    )
    out[i, 0] = fx
    out[i, 1] = fy
    out[i, 2] = level
    out[i, 3] = norm


@numba.njit(cache=True, parallel=True, nogil=True)
def batch_descent(
    packed: np.ndarray, points: np.ndarray, goals: np.ndarray, gains: np.ndarray, out: np.ndarray
) -> None:
    """``point_descent`` for many units at once: ``out[i] = (grad_x, grad_y, level, norm)``."""
    for i in numba.prange(points.shape[0]):
        _descent_row(packed, points, goals, gains, out, i)


@_jit
def _serial_descent(
    packed: np.ndarray, points: np.ndarray, goals: np.ndarray, gains: np.ndarray, out: np.ndarray
) -> None:
    for i in range(points.shape[0]):
        _descent_row(packed, points, goals, gains, out, i)


# Below this many pair evaluations, waking numba's thread pool costs more than
# it saves (measured: ~0.7 ms and 5-10 ms tail spikes for a single unit).
PARALLEL_MIN_PAIRS = 20_000


def descent_many(
    packed: np.ndarray, points: np.ndarray, goals: np.ndarray, gains: np.ndarray, out: np.ndarray
) -> None:
    """``batch_descent``, run serially when the batch is too small to pay for threads."""
    if points.shape[0] * max(packed.shape[0], 1) < PARALLEL_MIN_PAIRS:
        _serial_descent(packed, points, goals, gains, out)
    else:
        batch_descent(packed, points, goals, gains, out)
