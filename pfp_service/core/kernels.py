"""Compiled inner loops: the threat field's value and closed-form gradient, written once.

Everything here is a pure function of arrays and floats, compiled with numba.
A threat set travels as one packed ``(M, C)`` float64 array, one row per
threat with the columns of ``PACKED_COLUMNS`` (``C >= 17``), so a call unboxes
one array instead of seventeen.  The column indices below are the only place
those numbers appear.

A threat that sees over terrain carries its visibility in its own row: from
column ``VIS_DATA`` on, its window of lowest visible heights (``core.visibility``
packs it), so every kernel that evaluates a threat masks it by line of sight
without a second argument, and a row subset or a concatenation keeps each
window with its threat.  A row with ``VIS_NX == 0`` sees everywhere, and its
term is bit for bit the unmasked one.

``threat_term`` is the one per-threat formula: every kernel here and in
``cores`` sums or compares it (the gradient sums through ``add_term``: the
same pieces, leaving out a term too small to change a bit of the sums).
Its gradient is exact:  with ``z = x - xi``,
``P = Omega^-1``, ``a = omega^-1 alpha`` and ``u = a.z``,
``grad t = 2 phi2(z; Omega) (phi(u) a - Phi(u) P z)``.  A pair whose
Mahalanobis term exceeds ``Q_CUTOFF`` is skipped: there ``exp(-q/2)``
underflows to exactly 0.0, so skipping changes no bit of the result and keeps
far-away threats free (and never NaN).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "ACTIVE",
    "A_X",
    "A_Y",
    "P00",
    "P01",
    "P11",
    "PACKED_COLUMNS",
    "Q_CUTOFF",
    "SCALE",
    "VIS_CELL",
    "VIS_DATA",
    "VIS_DV",
    "VIS_HEIGHT",
    "VIS_NX",
    "VIS_NY",
    "VIS_SOFT",
    "VIS_X0",
    "VIS_Y0",
    "XI_X",
    "XI_Y",
    "add_term",
    "batch_descent",
    "batch_level",
    "batch_level_grad",
    "pack_row",
    "point_descent",
    "point_level",
    "point_level_grad",
    "raster_level",
    "sight",
    "threat_term",
]

# One row per threat: xi; P = Omega^-1 (three entries, it is symmetric);
# a = omega^-1 alpha; the leading constant (``ThreatField`` folds in the weight
# and, under ``peak``, divides by the peak density; ``Cores`` sets it so the
# mode is 1); 1.0 for a threat in force, 0.0 for one every kernel skips.
# Then its visibility window (``core.visibility``): columns and rows of lowest
# visible heights (0 columns: no window, it sees everywhere), the window's
# south-west point and cell in metres, the unit's height and the sigmoid's
# softness in metres, and a bound on |grad v| (``cull`` widens its bounds by
# it); the heights themselves, row by row, from ``VIS_DATA`` on.
PACKED_COLUMNS = (
    "xi_x",
    "xi_y",
    "p00",
    "p01",
    "p11",
    "a_x",
    "a_y",
    "scale",
    "active",
    "vis_nx",
    "vis_ny",
    "vis_x0",
    "vis_y0",
    "vis_cell",
    "vis_height",
    "vis_soft",
    "vis_dv",
)
(XI_X, XI_Y, P00, P01, P11, A_X, A_Y, SCALE, ACTIVE) = range(9)
(VIS_NX, VIS_NY, VIS_X0, VIS_Y0, VIS_CELL, VIS_HEIGHT, VIS_SOFT, VIS_DV) = range(9, 17)
VIS_DATA = len(PACKED_COLUMNS)

# exp(-x) == 0.0 in float64 for x > 745.14; 2 * 746 leaves a margin.
Q_CUTOFF = 1492.0
_INV_SQRT2 = 1.0 / math.sqrt(2.0)
_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)

_jit = numba.njit(cache=True, fastmath=False, nogil=True)


def pack_row(
    xi: tuple[float, float],
    precision: tuple[float, float, float],
    shape: tuple[float, float],
    scale: float,
) -> tuple[float, ...]:
    """One packed row, in ``PACKED_COLUMNS`` order (an active threat that sees everywhere)."""
    return (
        xi[0],
        xi[1],
        precision[0],
        precision[1],
        precision[2],
        shape[0],
        shape[1],
        scale,
        1.0,
    ) + _NO_SIGHT


_NO_SIGHT = (0.0,) * (len(PACKED_COLUMNS) - 9)


@numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
def sight(packed: np.ndarray, j: int, x: float, y: float, grad: bool) -> tuple[float, float, float]:
    """Threat ``j``'s visibility ``v`` at ``(x, y)`` in [0, 1] and, if ``grad``, its gradient.

    ``v = sigmoid((height - L(x)) / soft)``, ``L`` the lowest visible height
    interpolated bilinearly in the row's window; its gradient is the exact
    derivative of that surface (a cell edge takes the cell to the east or
    north, as ``TerrainGrid`` does).  Outside the window the point is clamped
    to its edge, so ``v`` stays continuous; there the threat's own term is
    below its floor anyway (the window is its reach).
    """
    nx = int(packed[j, VIS_NX])
    ny = int(packed[j, VIS_NY])
    cell = packed[j, VIS_CELL]
    fx = (x - packed[j, VIS_X0]) / cell
    fy = (y - packed[j, VIS_Y0]) / cell
    in_x = True
    in_y = True
    if not fx > 0.0:  # NaN lands here too, on the edge
        fx = 0.0
        in_x = False
    elif fx > nx - 1:
        fx = nx - 1.0
        in_x = False
    if not fy > 0.0:
        fy = 0.0
        in_y = False
    elif fy > ny - 1:
        fy = ny - 1.0
        in_y = False
    i = min(int(fx), nx - 2)
    k = min(int(fy), ny - 2)
    tx = fx - i
    ty = fy - k
    base = VIS_DATA + k * nx + i
    l00 = packed[j, base]
    l10 = packed[j, base + 1]
    l01 = packed[j, base + nx]
    l11 = packed[j, base + nx + 1]
    low = (1.0 - ty) * ((1.0 - tx) * l00 + tx * l10) + ty * ((1.0 - tx) * l01 + tx * l11)
    soft = packed[j, VIS_SOFT]
    arg = (packed[j, VIS_HEIGHT] - low) / soft
    if arg >= 0.0:  # the two forms of the logistic that never overflow
        v = 1.0 / (1.0 + math.exp(-arg))
    else:
        ez = math.exp(arg)
        v = ez / (1.0 + ez)
    if not grad:
        return v, 0.0, 0.0
    dv = -v * (1.0 - v) / (soft * cell)  # dv/dL, per cell of L's run
    gx = dv * ((1.0 - ty) * (l10 - l00) + ty * (l11 - l01)) if in_x else 0.0
    gy = dv * ((1.0 - tx) * (l01 - l00) + tx * (l11 - l10)) if in_y else 0.0
    return v, gx, gy


@numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
def _offset(packed: np.ndarray, j: int, x: float, y: float) -> tuple[float, float, float, float, float]:
    """``(zx, zy, pzx, pzy, q)``: the point from threat ``j``'s centre, ``P z``, and ``q = z.P z``."""
    zx = x - packed[j, XI_X]
    zy = y - packed[j, XI_Y]
    pzx = packed[j, P00] * zx + packed[j, P01] * zy
    pzy = packed[j, P01] * zx + packed[j, P11] * zy
    return zx, zy, pzx, pzy, zx * pzx + zy * pzy


@numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
def _skewed(
    packed: np.ndarray,
    j: int,
    x: float,
    y: float,
    zx: float,
    zy: float,
    pzx: float,
    pzy: float,
    e: float,
    grad: bool,
) -> tuple[float, float, float]:
    """Threat ``j``'s term from its Gaussian factor ``e``: the skew factor, the mask, the gradient."""
    ax = packed[j, A_X]
    ay = packed[j, A_Y]
    u = ax * zx + ay * zy
    cdf = 0.5 * math.erfc(-u * _INV_SQRT2)
    if not grad:
        if packed[j, VIS_NX] == 0.0:
            return e * cdf, 0.0, 0.0
        return e * cdf * sight(packed, j, x, y, False)[0], 0.0, 0.0
    pdf = _INV_SQRT2PI * math.exp(-0.5 * u * u)
    gx = e * (pdf * ax - cdf * pzx)
    gy = e * (pdf * ay - cdf * pzy)
    if packed[j, VIS_NX] == 0.0:
        return e * cdf, gx, gy
    # d(t v) = v dt + t dv: masked by line of sight, the gradient still exact
    t = e * cdf
    v, vx, vy = sight(packed, j, x, y, True)
    return t * v, gx * v + t * vx, gy * v + t * vy


@numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
def threat_term(
    packed: np.ndarray, j: int, x: float, y: float, floor: float, grad: bool
) -> tuple[float, float, float]:
    """Threat ``j``'s scaled level at ``(x, y)`` and, if ``grad``, its gradient.

    ``floor``: return zeros early once the Gaussian factor alone is below it
    (the skew factor is at most 1, so the level would be too); 0.0 never
    does.  Inactive rows and points past ``Q_CUTOFF`` give exact zeros.
    """
    if packed[j, ACTIVE] == 0.0:
        return 0.0, 0.0, 0.0
    zx, zy, pzx, pzy, q = _offset(packed, j, x, y)
    if q > Q_CUTOFF:
        return 0.0, 0.0, 0.0
    e = packed[j, SCALE] * math.exp(-0.5 * q)
    if e < floor:
        return 0.0, 0.0, 0.0
    return _skewed(packed, j, x, y, zx, zy, pzx, pzy, e, grad)


# A sum ``s`` with ``|s| > 2**-900`` has ``|s| * 2**-56`` exact and below an
# eighth of its last place; a term's bound below that leaves room for the
# term's own roundings, and a term below a quarter of the last place leaves
# every bit of ``s`` as it was (round to nearest): ``add_term``'s skip.
_ABSORBED = 2.0**-56
_LIMIT_MIN = 2.0**-956


@numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
def _absorbed(bound: float, total: float) -> bool:
    """Whether any term ``|t| <= bound`` (computed with a few roundings) added to ``total`` leaves it bit for bit."""
    limit = abs(total) * _ABSORBED
    return bound < limit and limit > _LIMIT_MIN


@numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
def add_term(
    packed: np.ndarray, j: int, x: float, y: float, val: float, gx: float, gy: float
) -> tuple[float, float, float]:
    """``(val, gx, gy)`` plus threat ``j``'s term and gradient: bit for bit ``+= threat_term(..., 0.0, True)``.

    A micro-optimisation (bench row: ``pfp bench engine``, 10,000 units x 100
    threats, the spread kernel call): where an unmasked threat's term is
    provably too small to change a bit of any of the three sums, its skew
    factor (an ``erfc`` and an ``exp``) is not computed.  The bounds:
    ``|t| <= e`` (``Phi <= 1``) and ``|grad t| <= e (|a| / 2 + |P z|)`` per axis
    (``phi <= 0.4``), doubled for rounding.  An accumulator never holds -0.0
    (it starts at +0.0), so skipping a zero term is exact too.
    """
    if packed[j, ACTIVE] == 0.0:
        return val, gx, gy
    zx, zy, pzx, pzy, q = _offset(packed, j, x, y)
    if q > Q_CUTOFF:
        return val, gx, gy
    e = packed[j, SCALE] * math.exp(-0.5 * q)
    if (
        _absorbed(e, val)
        and packed[j, VIS_NX] == 0.0
        and _absorbed(2.0 * e * (0.5 * abs(packed[j, A_X]) + abs(pzx)), gx)
        and _absorbed(2.0 * e * (0.5 * abs(packed[j, A_Y]) + abs(pzy)), gy)
    ):
        return val, gx, gy
    t, tx, ty = _skewed(packed, j, x, y, zx, zy, pzx, pzy, e, True)
    return val + t, gx + tx, gy + ty


@_jit
def point_level_grad(packed: np.ndarray, x: float, y: float) -> tuple[float, float, float]:
    """Weighted threat level and its gradient at one point."""
    val = 0.0
    gx = 0.0
    gy = 0.0
    for j in range(packed.shape[0]):
        val, gx, gy = add_term(packed, j, x, y, val, gx, gy)
    return val, gx, gy


@_jit
def point_level(packed: np.ndarray, x: float, y: float) -> float:
    """Weighted threat level at one point (no gradient)."""
    val = 0.0
    for j in range(packed.shape[0]):
        val += threat_term(packed, j, x, y, 0.0, False)[0]
    return val


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
def _parallel_level(packed: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
    for i in numba.prange(points.shape[0]):
        out[i] = point_level(packed, points[i, 0], points[i, 1])


@_jit
def _serial_level(packed: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
    for i in range(points.shape[0]):
        out[i] = point_level(packed, points[i, 0], points[i, 1])


def batch_level(packed: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
    """Level only at many points (no gradient): contour plots and exposure.

    Serial below ``PARALLEL_MIN_PAIRS_LEVEL`` point-threat pairs, as ``descent_many``.
    """
    if points.shape[0] * max(packed.shape[0], 1) < PARALLEL_MIN_PAIRS_LEVEL:
        _serial_level(packed, points, out)
    else:
        _parallel_level(packed, points, out)


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
# it saves (docs/operations.md, "Figures behind the code's choices").
PARALLEL_MIN_PAIRS = 20_000
# Level-only pairs are cheaper, so the pool pays later (path exposure, shortcut samples).
PARALLEL_MIN_PAIRS_LEVEL = 2_000_000


def descent_many(
    packed: np.ndarray, points: np.ndarray, goals: np.ndarray, gains: np.ndarray, out: np.ndarray
) -> None:
    """``batch_descent``, run serially when the batch is too small to pay for threads."""
    if points.shape[0] * max(packed.shape[0], 1) < PARALLEL_MIN_PAIRS:
        _serial_descent(packed, points, goals, gains, out)
    else:
        batch_descent(packed, points, goals, gains, out)


@numba.njit(cache=True, nogil=True)
def raster_level(packed: np.ndarray, x0: float, y0: float, h: float, floor: float, out: np.ndarray) -> None:
    """``out[i, k] +=`` the level at ``(x0 + i h, y0 + k h)``, each threat only where its term is ``>= floor``.

    Culled by construction: threat j reaches ``floor`` only where
    ``q <= 2 ln(scale_j / floor)``, an ellipse whose bounding box is all that
    is visited, so a grid over many small threats costs the sum of their boxes.
    The sum differs from ``batch_level`` only by terms below ``floor``.
    """
    nx, ny = out.shape
    for j in range(packed.shape[0]):
        s = packed[j, SCALE]
        if packed[j, ACTIVE] == 0.0 or s < floor:
            continue
        qmax = min(2.0 * math.log(s / floor), Q_CUTOFF)
        p00, p01, p11 = packed[j, P00], packed[j, P01], packed[j, P11]
        det = p00 * p11 - p01 * p01
        ex = math.sqrt(qmax * p11 / det) + h
        ey = math.sqrt(qmax * p00 / det) + h
        cx, cy = packed[j, XI_X], packed[j, XI_Y]
        i0 = max(0, math.floor((cx - ex - x0) / h))
        i1 = min(nx - 1, math.ceil((cx + ex - x0) / h))
        k0 = max(0, math.floor((cy - ey - y0) / h))
        k1 = min(ny - 1, math.ceil((cy + ey - y0) / h))
        for i in range(i0, i1 + 1):
            x = x0 + i * h
            for k in range(k0, k1 + 1):
                out[i, k] += threat_term(packed, j, x, y0 + k * h, floor, False)[0]
