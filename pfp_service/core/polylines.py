"""Polylines over a threat field: their cost, their clearance of the cores, shortcuts and resampling.

``shortcut`` turns a run of grid edges (``grid.GridGraph``'s routes) into one straight segment
whenever that costs no more ``J = length + lambda * exposure`` (and, given cores, enters none),
which removes the grid's heading quantisation; ``resample`` spaces a polyline evenly again, for
a stepper to follow (``pieces`` gives its leg counts).  ``polyline_clear`` and ``segment_hits``
test a path against the cores.  Apart from the grid graph because the escapes, routes and
optimal planner use them on any polyline, not only on grid routes.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.cores import Cores
from pfp_service.core.cull import cell_level, index_of, point_level
from pfp_service.core.threat import ThreatField

__all__ = [
    "pieces",
    "polyline_clear",
    "resample",
    "segment_costs",
    "segment_hits",
    "shortcut",
    "shortcut_kept",
]

_WINDOW = 48  # grid edges a shortcut may replace at once
_SAMPLES = 17  # Simpson points on a candidate shortcut


def segment_costs(field: ThreatField, a: np.ndarray, b: np.ndarray, lam: float) -> np.ndarray:
    """``J`` of straight segments ``a[k] -> b[k]`` by composite Simpson on ``_SAMPLES`` points."""
    t = np.linspace(0.0, 1.0, _SAMPLES)
    pts = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    index = index_of(field)  # many threats: each point sums only its cell's (cull.py)
    lv = field.level_culled(pts) if index is None else cell_level(index, pts)
    w = np.ones(_SAMPLES)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    length = np.hypot(*(b - a).T)
    return np.asarray(length + lam * length * (lv @ w) / (3.0 * (_SAMPLES - 1)))


def shortcut(field: ThreatField, pts: np.ndarray, lam: float, cores: Cores | None) -> np.ndarray:
    """Greedily replace runs of segments by straight ones that cost no more."""
    return np.asarray(pts[shortcut_kept(field, pts, lam, cores)])


@numba.njit(cache=True, nogil=True)
def _segment_cost(  # type: ignore[no-untyped-def]
    packed, grid, indptr, indices, ax, ay, bx, by, lam, w, limit
):  # fmt: skip
    """``segment_costs`` of one segment, each sample's level from its cell of the index (``cull._cell_level``).

    Past ``limit`` it stops early and answers ``inf``: every term is at least
    zero, so the running sum (rounded up or down, never down past a smaller
    sum) only grows, and the whole would exceed ``limit`` too.
    """
    dx, dy = bx - ax, by - ay
    length = math.hypot(dx, dy)
    if length > limit:
        return math.inf
    scale = lam * length / (3.0 * (_SAMPLES - 1))
    acc = 0.0
    for s in range(_SAMPLES):
        t = s * (1.0 / (_SAMPLES - 1))
        acc += point_level(packed, grid, indptr, indices, ax + t * dx, ay + t * dy) * w[s]
        if length + scale * acc > limit * (1.0 + 1e-9):  # clearly past it, whatever the rounding
            return math.inf
    return length + lam * length * acc / (3.0 * (_SAMPLES - 1))


@numba.njit(cache=True, nogil=True)
def _in_core(cpacked, boxes, fraction, x, y):  # type: ignore[no-untyped-def]
    for j in range(cpacked.shape[0]):
        near = boxes[j, 0] <= x <= boxes[j, 2] and boxes[j, 1] <= y <= boxes[j, 3]
        if near and kernels.threat_term(cpacked, j, x, y, fraction, False)[0] >= fraction:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _clear(cpacked, boxes, fraction, ax, ay, bx, by, spacing):  # type: ignore[no-untyped-def]
    """The segment enters no threat core, sampled as ``Cores.first_hit`` samples it (``densify``)."""
    n = 1
    if math.isfinite(spacing):
        n = max(1, math.ceil(math.hypot(bx - ax, by - ay) / spacing))
    for k in range(n + 1):
        t = k / n
        if _in_core(cpacked, boxes, fraction, ax + t * (bx - ax), ay + t * (by - ay)):
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _segment_hits(cpacked, boxes, fraction, pts, spacing):  # type: ignore[no-untyped-def]
    """Per segment of ``pts``: does it enter a core (sampled as ``Cores.segment_hits`` samples it)?"""
    out = np.zeros(max(pts.shape[0] - 1, 0), dtype=np.bool_)
    for k in range(pts.shape[0] - 1):
        out[k] = not _clear(
            cpacked, boxes, fraction, pts[k, 0], pts[k, 1], pts[k + 1, 0], pts[k + 1, 1], spacing
        )
    return out


@numba.njit(cache=True, nogil=True)
def _polyline_clear(cpacked, boxes, fraction, pts, spacing):  # type: ignore[no-untyped-def]
    """No point of ``Cores.densify(pts)`` (the very points, computed as it computes them) lies in a core."""
    m = pts.shape[0]
    counts = np.ones(max(m - 1, 0), dtype=np.int64)
    dense = False
    if math.isfinite(spacing):
        for k in range(m - 1):
            d = math.hypot(pts[k + 1, 0] - pts[k, 0], pts[k + 1, 1] - pts[k, 1])
            counts[k] = max(1, math.ceil(d / spacing))
            dense = dense or counts[k] > 1
    if not dense:  # densify gives the path itself
        for k in range(m):  # noqa: SIM110 (compiled: no generators)
            if _in_core(cpacked, boxes, fraction, pts[k, 0], pts[k, 1]):
                return False
        return True
    if _in_core(cpacked, boxes, fraction, pts[0, 0], pts[0, 1]):
        return False
    for k in range(m - 1):
        dx, dy = pts[k + 1, 0] - pts[k, 0], pts[k + 1, 1] - pts[k, 1]
        for r in range(1, counts[k] + 1):
            t = r / counts[k]
            if _in_core(cpacked, boxes, fraction, pts[k, 0] + t * dx, pts[k, 1] + t * dy):
                return False
    return True


def polyline_clear(cores: Cores, path: np.ndarray) -> bool:
    """``not cores.first_hit(path)`` for the threat cores, compiled; ``False`` when zones are in (ask ``first_hit``)."""
    if cores.zones:
        return False
    if not len(cores.packed):
        return True
    return bool(
        _polyline_clear(
            cores.packed,
            cores.boxes,
            float(cores.fraction),
            np.ascontiguousarray(np.asarray(path, dtype=np.float64).reshape(-1, 2)),
            float(cores.min_spread_m / 4.0),
        )
    )


def segment_hits(cores: Cores, pts: np.ndarray) -> np.ndarray:
    """``cores.segment_hits(pts)``, compiled with each sample tested only against the cores whose box holds it."""
    if cores.zones or len(pts) < 2 or not len(cores.packed):
        return cores.segment_hits(pts)
    out: np.ndarray = _segment_hits(
        cores.packed,
        cores.boxes,
        float(cores.fraction),
        np.ascontiguousarray(pts, dtype=np.float64),
        float(cores.min_spread_m / 4.0),
    )
    return out


@numba.njit(cache=True, nogil=True)
def _shortcut_kept(  # type: ignore[no-untyped-def]
    pts, lam, packed, grid, indptr, indices, check, cpacked, boxes, fraction, spacing
):  # fmt: skip
    """``shortcut_kept`` compiled: from each kept point the farthest candidate first, and only until one passes."""
    n = pts.shape[0]
    w = np.ones(_SAMPLES)
    for s in range(1, _SAMPLES - 1):
        w[s] = 4.0 if s % 2 == 1 else 2.0
    prefix = np.zeros(n)
    for k in range(n - 1):
        seg = _segment_cost(
            packed,
            grid,
            indptr,
            indices,
            pts[k, 0],
            pts[k, 1],
            pts[k + 1, 0],
            pts[k + 1, 1],
            lam,
            w,
            math.inf,
        )
        prefix[k + 1] = prefix[k] + seg
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    m = 1
    i = 0
    while i < n - 1:
        best = i + 1
        for j in range(min(n - 1, i + _WINDOW), i + 1, -1):
            limit = (prefix[j] - prefix[i]) * (1.0 + 1e-12)
            direct = _segment_cost(
                packed, grid, indptr, indices, pts[i, 0], pts[i, 1], pts[j, 0], pts[j, 1], lam, w, limit
            )
            if direct > limit:
                continue
            if not check or _clear(
                cpacked, boxes, fraction, pts[i, 0], pts[i, 1], pts[j, 0], pts[j, 1], spacing
            ):
                best = j
                break
        keep[m] = best
        m += 1
        i = best
    return keep[:m].copy()


def shortcut_kept(field: ThreatField, pts: np.ndarray, lam: float, cores: Cores | None) -> np.ndarray:
    """The indices of ``pts`` that ``shortcut`` keeps, first and last included.

    Greedy and forward-looking: which points are kept from index ``i`` on
    depends only on ``pts[i:]``.  From each kept point the candidates are
    tried farthest first, and a candidate's ``J`` is computed only when it is
    tried (compiled, where the field has a cull index and no zone is in the
    cores): the first that costs no more and enters no core is the one the
    whole window's evaluation would pick.
    """
    if len(pts) < 3:
        return np.arange(len(pts))
    index = index_of(field)
    if index is not None and (cores is None or not cores.zones):
        grid = (index.origin[0], index.origin[1], index.cell, index.nx, index.ny)
        check = cores is not None and len(cores.packed) > 0
        cp = cores.packed if check and cores is not None else np.zeros((0, len(kernels.PACKED_COLUMNS)))
        boxes = cores.boxes if check and cores is not None else np.zeros((0, 4))
        fraction = float(cores.fraction) if cores is not None else 1.0
        spacing = cores.min_spread_m / 4.0 if cores is not None else math.inf
        out: np.ndarray = _shortcut_kept(
            np.ascontiguousarray(pts, dtype=np.float64),
            float(lam),
            index.packed,
            grid,
            index.indptr,
            index.indices,
            check,
            np.ascontiguousarray(cp),
            np.ascontiguousarray(boxes),
            fraction,
            float(spacing),
        )
        return out
    return _shortcut_kept_numpy(field, pts, lam, cores)


def _shortcut_kept_numpy(field: ThreatField, pts: np.ndarray, lam: float, cores: Cores | None) -> np.ndarray:
    """``shortcut_kept`` with every candidate of a window evaluated at once (any field, zones included)."""
    seg = segment_costs(field, pts[:-1], pts[1:], lam)
    prefix = np.concatenate([[0.0], np.cumsum(seg)])
    keep = [0]
    i = 0
    n = len(pts)
    while i < n - 1:
        js = np.arange(i + 2, min(n, i + _WINDOW + 1))
        best = i + 1
        if len(js):
            direct = segment_costs(field, np.repeat(pts[i : i + 1], len(js), axis=0), pts[js], lam)
            ok = direct <= (prefix[js] - prefix[i]) * (1.0 + 1e-12)
            for j in js[ok][::-1]:
                if cores is None or not cores.first_hit(pts[[i, j]]):
                    best = int(j)
                    break
        keep.append(best)
        i = best
    return np.array(keep)


def pieces(pts: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Each segment of ``pts`` as its delta, and how many even pieces of at most ``spacing`` it is split into."""
    seg = np.diff(pts, axis=0)
    return seg, np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / spacing)).astype(np.int64)


def resample(pts: np.ndarray, spacing: float) -> np.ndarray:
    """``pts`` with every segment split evenly into pieces of at most ``spacing`` (``pieces``)."""
    seg, k = pieces(pts, spacing)
    parts = [pts[:1]]
    for a, d, m in zip(pts[:-1], seg, k.tolist()):
        parts.append(a + (np.arange(1, m + 1)[:, None] / m) * d)
    return np.concatenate(parts)
