"""Culling: advise many units while evaluating only the threats near each, with a proven bound.

The rule.  Threat ``j`` is skipped at ``x`` only where its Mahalanobis term
``q = z.P z`` is at least ``q_cut`` (default ``Q_CUT``, 50).  There, from the
kernel's closed form ``grad t = e (phi(u) a - Phi(u) P z)`` with
``e = scale exp(-q/2)``::

    |grad t_j| <= scale_j exp(-q/2) (|a_j| / sqrt(2 pi) + sqrt(lmax(P_j) q))

which decreases in ``q`` for ``q >= 1``; so every skipped threat contributes
at most ``G_j = that bound at q_cut``, and all of them together at most
``B = sum_j G_j`` over the threats the unit's cell does not list.  A unit
whose kept gradient ``g``
(threats near it plus the goal term) satisfies ``B <= |g| * RELATIVE_BOUND``
keeps the culled answer: its direction is off by at most
``asin(RELATIVE_BOUND)`` = 1e-6 rad (0.00006 degree), far inside the 0.1 degree the service
promises, and previews (which evaluate every threat) still replay it.  Any
other unit -- near a stationary point, or in a field whose bound is loose --
is evaluated with every threat instead.  The level is off by at most
``sum_j scale_j exp(-q_cut / 2)``.

The index.  Each threat's ``q <= q_cut`` region is an ellipse; its bounding
box is inserted into the cells of one uniform grid (cell side from the
median box, at most ``MAX_CELLS`` cells), stored as CSR arrays.  A unit
evaluates the threats listed in its cell: every threat not listed has
``q >= q_cut`` there.  Building costs O(threats x cells each covers);
a tick costs O(units x nearby threats).
"""

from __future__ import annotations

import math
import weakref
from typing import Any

import numba
import numpy as np

from pfp_service.core import kernels, steprule
from pfp_service.core.kernels import A_X, A_Y, ACTIVE, P00, P01, P11, SCALE, VIS_DV, XI_X, XI_Y
from pfp_service.core.zones import ZoneSet

__all__ = [
    "MIN_THREATS",
    "Q_CUT",
    "RELATIVE_BOUND",
    "CullIndex",
    "cell_level",
    "corridors_meet",
    "index_of",
    "influence_boxes",
    "point_level",
    "predict",
]

Q_CUT = 50.0  # 80 listed 26 threats a unit in the spread 10,000 x 1,000 table, 50 lists 18; none fell back
RELATIVE_BOUND = 1e-6  # sin of the largest direction error a culled answer may carry (0.00006 deg)
MAX_CELLS = 512 * 512
MIN_THREATS = 32  # below this a plain loop over every threat is as fast


class CullIndex:
    """Where each threat matters, for one packed field (``ThreatField.packed``)."""

    def __init__(self, packed: np.ndarray, q_cut: float = Q_CUT) -> None:
        self.packed = packed
        self.q_cut = q_cut
        act = packed[:, ACTIVE] != 0.0
        p00, p01, p11 = packed[:, P00], packed[:, P01], packed[:, P11]
        det = p00 * p11 - p01 * p01
        half = 0.5 * (p00 + p11)
        lmax = half + np.sqrt(np.maximum(half * half - det, 0.0))
        a = np.hypot(packed[:, A_X], packed[:, A_Y])
        decay = math.exp(-0.5 * q_cut)
        # a threat that sees adds t |grad v| <= scale decay |grad v|_max to its gradient (d(t v) = v dt + t dv)
        g = (
            packed[:, SCALE]
            * decay
            * (a / math.sqrt(2.0 * math.pi) + np.sqrt(lmax * q_cut) + packed[:, VIS_DV])
        )
        g = np.where(act, g, 0.0)
        self.bound = float(np.sum(g))  # B: every threat's bound; a cell's own B leaves out those it lists
        self._g = g
        self.level_bound = float(np.sum(packed[act, SCALE]) * decay)
        ex = np.sqrt(q_cut * p11 / det)
        ey = np.sqrt(q_cut * p00 / det)
        idx = np.flatnonzero(act)
        if idx.size == 0:
            self._grid(np.zeros((0, 4)), idx)
            return
        boxes = np.stack(
            [
                packed[idx, XI_X] - ex[idx],
                packed[idx, XI_Y] - ey[idx],
                packed[idx, XI_X] + ex[idx],
                packed[idx, XI_Y] + ey[idx],
            ],
            axis=1,
        )
        self._grid(boxes, idx)

    def _grid(self, boxes: np.ndarray, idx: np.ndarray) -> None:
        if len(idx) == 0:
            self.origin = (0.0, 0.0)
            self.cell = 1.0
            self.nx = self.ny = 1
            self.indptr = np.zeros(2, dtype=np.int64)
            self.indices = np.zeros(0, dtype=np.int64)
            self.cell_bound = np.zeros(1)
            return
        x0, y0 = boxes[:, 0].min(), boxes[:, 1].min()
        x1, y1 = boxes[:, 2].max(), boxes[:, 3].max()
        side = float(np.median(np.maximum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1])))
        # a quarter of the median box: a threat spans about 5 x 5 cells, a unit sees about its box's worth
        cell = max(0.25 * side, math.sqrt((x1 - x0) * (y1 - y0) / MAX_CELLS), 1e-9)
        nx = max(1, math.ceil((x1 - x0) / cell))
        ny = max(1, math.ceil((y1 - y0) / cell))
        i0 = np.clip(((boxes[:, 0] - x0) // cell).astype(np.int64), 0, nx - 1)
        i1 = np.clip(((boxes[:, 2] - x0) // cell).astype(np.int64), 0, nx - 1)
        k0 = np.clip(((boxes[:, 1] - y0) // cell).astype(np.int64), 0, ny - 1)
        k1 = np.clip(((boxes[:, 3] - y0) // cell).astype(np.int64), 0, ny - 1)
        counts = (i1 - i0 + 1) * (k1 - k0 + 1)
        cells = np.empty(int(counts.sum()), dtype=np.int64)
        owner = np.repeat(idx, counts)
        _fill(i0, i1, k0, k1, nx, cells)
        order = np.argsort(cells, kind="stable")
        self.indices = owner[order].astype(np.int64)
        self.indptr = np.zeros(nx * ny + 1, dtype=np.int64)
        np.cumsum(np.bincount(cells, minlength=nx * ny), out=self.indptr[1:])
        self.origin = (float(x0), float(y0))
        self.cell = float(cell)
        self.nx, self.ny = nx, ny
        listed = np.zeros(nx * ny)
        np.add.at(listed, cells[order], self._g[self.indices])
        # B of a cell: what every threat it does not list could add there (float-safe: never below 0)
        self.cell_bound = np.maximum(self.bound - listed, 0.0) * (1.0 + 1e-12) + 1e-300

    def descent(self, points: np.ndarray, goals: np.ndarray, gains: np.ndarray, out: np.ndarray) -> int:
        """``kernels.descent_many`` with culling: ``out[i] = (grad_x, grad_y, level, norm)``.

        Returns:
            How many units needed every threat (the bound did not hold for them).
        """
        flags = np.zeros(points.shape[0], dtype=np.bool_)
        pairs = points.shape[0] * (self.indices.size / max(self.nx * self.ny, 1) + 1.0)
        kernel = _culled_descent_parallel if pairs >= kernels.PARALLEL_MIN_PAIRS else _culled_descent
        kernel(
            self.packed,
            points,
            goals,
            gains,
            (self.origin[0], self.origin[1], self.cell, self.nx, self.ny),
            self.indptr,
            self.indices,
            self.cell_bound / RELATIVE_BOUND,
            self.bound / RELATIVE_BOUND,
            out,
            flags,
        )
        full = np.flatnonzero(flags)
        if full.size:
            sub = np.empty((full.size, 4))
            kernels.descent_many(self.packed, points[full], goals[full], gains[full], sub)
            out[full] = sub
        return int(full.size)


@numba.njit(cache=True, nogil=True)
def _fill(i0: np.ndarray, i1: np.ndarray, k0: np.ndarray, k1: np.ndarray, nx: int, cells: np.ndarray) -> None:
    n = 0
    for t in range(i0.shape[0]):
        for k in range(k0[t], k1[t] + 1):
            for i in range(i0[t], i1[t] + 1):
                cells[n] = k * nx + i
                n += 1


@numba.njit(cache=True, nogil=True, inline="always")
def _culled_row(
    packed: np.ndarray,
    points: np.ndarray,
    goals: np.ndarray,
    gains: np.ndarray,
    grid: tuple[float, float, float, int, int],
    indptr: np.ndarray,
    indices: np.ndarray,
    cell_need: np.ndarray,
    need_outside: float,
    out: np.ndarray,
    flags: np.ndarray,
    i: int,
) -> None:
    """Unit ``i``: the threats its cell lists, the goal term, and whether the bound holds there."""
    ox, oy, cell, nx, ny = grid
    x = points[i, 0]
    y = points[i, 1]
    val = 0.0
    gx = 0.0
    gy = 0.0
    inside = math.isfinite(x) and math.isfinite(y)
    ci = math.floor((x - ox) / cell) if inside else -1
    ck = math.floor((y - oy) / cell) if inside else -1
    need = need_outside
    if 0 <= ci < nx and 0 <= ck < ny:
        c = ck * nx + ci
        need = cell_need[c]
        for p in range(indptr[c], indptr[c + 1]):
            val, gx, gy = kernels.add_term(packed, indices[p], x, y, val, gx, gy)
    fx = gx - 2.0 * gains[i] * (goals[i, 0] - x)
    fy = gy - 2.0 * gains[i] * (goals[i, 1] - y)
    norm = math.sqrt(fx * fx + fy * fy)
    out[i, 0] = fx
    out[i, 1] = fy
    out[i, 2] = val
    out[i, 3] = norm
    flags[i] = not (norm >= need)  # also true for a NaN norm: the full kernel decides


@numba.njit(cache=True, nogil=True)
def _culled_descent(packed, points, goals, gains, grid, indptr, indices, cell_need, need_outside, out, flags):  # type: ignore[no-untyped-def]
    for i in range(points.shape[0]):
        _culled_row(
            packed, points, goals, gains, grid, indptr, indices, cell_need, need_outside, out, flags, i
        )


@numba.njit(cache=True, parallel=True, nogil=True)
def _culled_descent_parallel(  # type: ignore[no-untyped-def]
    packed, points, goals, gains, grid, indptr, indices, cell_need, need_outside, out, flags
):
    for i in numba.prange(points.shape[0]):
        _culled_row(
            packed, points, goals, gains, grid, indptr, indices, cell_need, need_outside, out, flags, i
        )


_NO_ZONES = ZoneSet()


def predict(
    packed: np.ndarray,
    index: CullIndex | None,
    points: np.ndarray,
    units: np.ndarray,
    steps: int,
    zones: ZoneSet | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Plain steepest descent of many units for ``steps`` steps, in one compiled call.

    Among keep-out ``zones`` each step is ``steprule.judge_zoned``'s, as the stepper's.

    Each step is ``descent`` (culled through ``index`` where the bound holds,
    every threat elsewhere; every threat when ``index`` is ``None``), judged
    by ``steprule.judge`` for row ``i`` of ``units`` (``steprule.unit``
    without a watch: its goal, gain, tolerance, step and bounds): the unit
    stops at its goal, outside its bounds, or where the gradient vanishes or
    is not finite, and its last step ends on the goal when that is within a
    step.

    Returns:
        ``(trail, lengths)``: ``trail[i, :lengths[i]]`` are unit ``i``'s
        positions, ``points[i]`` first.
    """
    pts = np.array(points, dtype=np.float64).reshape(-1, 2)
    n = pts.shape[0]
    trail = np.empty((n, steps + 1, 2))
    lengths = np.empty(n, dtype=np.int64)
    goals = np.ascontiguousarray(units[:, steprule.GOAL_X : steprule.GOAL_Y + 1])
    gains = np.ascontiguousarray(units[:, steprule.GAIN])
    if index is not None:
        grid = (index.origin[0], index.origin[1], index.cell, index.nx, index.ny)
        args = (
            grid,
            index.indptr,
            index.indices,
            index.cell_bound / RELATIVE_BOUND,
            index.bound / RELATIVE_BOUND,
        )
        pairs = n * steps * (index.indices.size / max(index.nx * index.ny, 1) + 1.0)
    else:
        args = ((0.0, 0.0, 1.0, 1, 1), np.zeros(2, np.int64), np.zeros(0, np.int64), np.zeros(1), 0.0)
        pairs = n * steps * max(packed.shape[0], 1)
    kernel = _predict_parallel if pairs >= kernels.PARALLEL_MIN_PAIRS else _predict_serial
    zp = (zones if zones is not None else _NO_ZONES).packed()
    kernel(packed, pts, goals, gains, units, steps, index is not None, *args, trail, lengths, *zp)
    return trail, lengths


@numba.njit(cache=True, nogil=True, inline="always")
def _predict_row(  # type: ignore[no-untyped-def]
    packed, pts, goals, gains, units, steps, culled, grid, indptr, indices, cell_need, need_outside,
    trail, lengths, out, flags, i, edges, offsets, circles, boxes,
):  # fmt: skip
    trail[i, 0, 0] = pts[i, 0]
    trail[i, 0, 1] = pts[i, 1]
    length = 1
    unit = units[i]
    for _k in range(steps):
        x = pts[i, 0]
        y = pts[i, 1]
        if steprule.judge(unit, x, y, 0.0, 0.0, 0.0, steprule.CHECK)[0] != steprule.GO:
            break  # arrived, out of bounds or not finite: no gradient needed
        if culled:
            _culled_row(
                packed, pts, goals, gains, grid, indptr, indices, cell_need, need_outside, out, flags, i
            )
            if flags[i]:
                kernels._descent_row(packed, pts, goals, gains, out, i)
        else:
            kernels._descent_row(packed, pts, goals, gains, out, i)
        code, _dx, _dy, _dist, _move, tx, ty = steprule.judge_zoned(
            unit, edges, offsets, circles, boxes, x, y, out[i, 0], out[i, 1], out[i, 3]
        )
        if code != steprule.GO:
            break
        pts[i, 0] = tx
        pts[i, 1] = ty
        trail[i, length, 0] = tx
        trail[i, length, 1] = ty
        length += 1
    lengths[i] = length


@numba.njit(cache=True, nogil=True)
def _predict_serial(  # type: ignore[no-untyped-def]
    packed, pts, goals, gains, units, steps, culled, grid, indptr, indices, cell_need, need_outside,
    trail, lengths, edges, offsets, circles, boxes,
):  # fmt: skip
    out = np.empty((pts.shape[0], 4))
    flags = np.zeros(pts.shape[0], dtype=np.bool_)
    for i in range(pts.shape[0]):
        _predict_row(
            packed, pts, goals, gains, units, steps, culled, grid, indptr, indices, cell_need, need_outside,
            trail, lengths, out, flags, i, edges, offsets, circles, boxes,
        )  # fmt: skip


@numba.njit(cache=True, nogil=True, parallel=True)
def _predict_parallel(  # type: ignore[no-untyped-def]
    packed, pts, goals, gains, units, steps, culled, grid, indptr, indices, cell_need, need_outside,
    trail, lengths, edges, offsets, circles, boxes,
):  # fmt: skip
    out = np.empty((pts.shape[0], 4))
    flags = np.zeros(pts.shape[0], dtype=np.bool_)
    for i in numba.prange(pts.shape[0]):
        _predict_row(
            packed, pts, goals, gains, units, steps, culled, grid, indptr, indices, cell_need, need_outside,
            trail, lengths, out, flags, i, edges, offsets, circles, boxes,
        )  # fmt: skip


def influence_boxes(packed: np.ndarray, q_cut: float = Q_CUT) -> np.ndarray:
    """``(M, 4)`` boxes ``(x0, y0, x1, y1)`` outside which each threat's ``q >= q_cut`` (it is culled there)."""
    p00, p01, p11 = packed[:, P00], packed[:, P01], packed[:, P11]
    det = p00 * p11 - p01 * p01
    ex = np.sqrt(q_cut * p11 / det)
    ey = np.sqrt(q_cut * p00 / det)
    return np.stack(
        [packed[:, XI_X] - ex, packed[:, XI_Y] - ey, packed[:, XI_X] + ex, packed[:, XI_Y] + ey], axis=1
    )


def corridors_meet(
    starts: np.ndarray, ends: np.ndarray, boxes: np.ndarray, widen: float = 0.25
) -> np.ndarray:
    """Which units' corridors meet any box: ``(N,)`` booleans.

    A unit's corridor is the bounding box of its straight segment ``start -> end``,
    widened on every side by ``widen`` times the segment's length: descent bends
    round threats, but not farther than that from the straight line in any
    field it would arrive in.
    """
    lo = np.minimum(starts, ends)
    hi = np.maximum(starts, ends)
    pad = widen * np.hypot(*(ends - starts).T)[:, None]
    lo = lo - pad
    hi = hi + pad
    hit = np.zeros(starts.shape[0], dtype=bool)
    for x0, y0, x1, y1 in boxes:
        hit |= (lo[:, 0] <= x1) & (hi[:, 0] >= x0) & (lo[:, 1] <= y1) & (hi[:, 1] >= y0)
    return hit


@numba.njit(cache=True, nogil=True)
def point_level(packed, grid, indptr, indices, x, y):  # type: ignore[no-untyped-def]
    """The level at ``(x, y)`` from the threats its cell of the index lists (0 off the index or not finite)."""
    ox, oy, cell, nx, ny = grid
    v = 0.0
    if math.isfinite(x) and math.isfinite(y):
        ci = math.floor((x - ox) / cell)
        ck = math.floor((y - oy) / cell)
        if 0 <= ci < nx and 0 <= ck < ny:
            c = ck * nx + ci
            for p in range(indptr[c], indptr[c + 1]):
                v += kernels.threat_term(packed, indices[p], x, y, 0.0, False)[0]
    return v


@numba.njit(cache=True, nogil=True)
def _cell_level(packed, pts, grid, indptr, indices, out):  # type: ignore[no-untyped-def]
    for i in range(pts.shape[0]):
        out[i] = point_level(packed, grid, indptr, indices, pts[i, 0], pts[i, 1])


def cell_level(index: CullIndex, points: np.ndarray) -> np.ndarray:
    """The level at ``points`` from the threats each point's cell lists (off by at most ``index.level_bound``)."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    out = np.empty(len(pts))
    grid = (index.origin[0], index.origin[1], index.cell, index.nx, index.ny)
    _cell_level(index.packed, pts, grid, index.indptr, index.indices, out)
    return out.reshape(np.shape(points)[:-1])


_INDEX: weakref.WeakKeyDictionary[Any, CullIndex | None] = weakref.WeakKeyDictionary()


def index_of(field: Any) -> CullIndex | None:
    """A ``ThreatField``'s index, built once per field (fields are immutable); ``None`` below ``MIN_THREATS``."""
    if len(field) < MIN_THREATS:
        return None
    got = _INDEX.get(field)
    if got is None:
        got = _INDEX[field] = CullIndex(field.packed)
    return got
