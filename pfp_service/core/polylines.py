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

from pfp_service.core import kernels, zone_kernels
from pfp_service.core.cores import Cores
from pfp_service.core.cull import cell_level, index_of, point_level
from pfp_service.core.threat import ThreatField
from pfp_service.core.visibility import finest_cell

__all__ = [
    "SIGHT_SPACING",
    "pieces",
    "polyline_clear",
    "resample",
    "sample_spacing",
    "segment_costs",
    "segment_hits",
    "shortcut",
    "shortcut_kept",
]

_WINDOW = 48  # grid edges a shortcut may replace at once
_CHUNK = 8  # candidates priced at once, farthest first (``_shortcut_kept_numpy``)
_SAMPLES = 17  # Simpson points on a candidate shortcut, at least
_MAX_INTERVALS = 4096  # Simpson intervals on a candidate shortcut, at most
SIGHT_SPACING = 1.0  # of the finest visibility window's cell: the most a masked field's samples lie apart


def sample_spacing(field: ThreatField) -> float:
    """The most two Simpson samples of a segment may lie apart under ``field`` (``inf``: no bound).

    An unmasked level is smooth over a threat's spread, and ``_SAMPLES``
    points a segment price it.  A masked one steps from hidden to seen over
    a visibility window's cell (``visibility.finest_cell``), so a long
    candidate priced by a fixed count of points can fall between the seen
    patches and look cheaper than the grid edges it replaces, while the
    path walked (and measured at every step) is not.
    """
    return SIGHT_SPACING * finest_cell(field.packed)


@numba.njit(cache=True, nogil=True)
def _intervals(length: float, spacing: float) -> int:
    """Simpson intervals (even) on a segment ``length`` long: ``_SAMPLES - 1``, or more to keep within ``spacing``."""
    n = _SAMPLES - 1
    if math.isfinite(spacing) and spacing > 0.0 and length > n * spacing:
        n = min(_MAX_INTERVALS, 2 * math.ceil(0.5 * length / spacing))
    return n


def segment_costs(
    field: ThreatField, a: np.ndarray, b: np.ndarray, lam: float, spacing: float | None = None
) -> np.ndarray:
    """``J`` of straight segments ``a[k] -> b[k]`` by composite Simpson on ``_SAMPLES`` points at least.

    Over a masked field the samples lie at most ``spacing`` apart (default
    ``sample_spacing(field)``): all the segments of one call on the count
    the longest needs.
    """
    spacing = sample_spacing(field) if spacing is None else spacing
    length = np.hypot(*(b - a).T)
    n = int(_intervals(float(length.max()) if len(length) else 0.0, spacing))
    t = np.linspace(0.0, 1.0, n + 1)
    pts = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    index = index_of(field)  # many threats: each point sums only its cell's (cull.py)
    lv = field.level(pts) if index is None else cell_level(index, pts)
    w = np.ones(n + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return np.asarray(length + lam * length * (lv @ w) / (3.0 * n))


def shortcut(field: ThreatField, pts: np.ndarray, lam: float, cores: Cores | None) -> np.ndarray:
    """Greedily replace runs of segments by straight ones that cost no more."""
    return np.asarray(pts[shortcut_kept(field, pts, lam, cores)])


@numba.njit(cache=True, nogil=True)
def _segment_cost(  # type: ignore[no-untyped-def]
    packed, grid, indptr, indices, ax, ay, bx, by, lam, spacing, limit
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
    n = _intervals(length, spacing)
    scale = lam * length / (3.0 * n)
    acc = 0.0
    for s in range(n + 1):
        t = s * (1.0 / n)
        w = 1.0 if s == 0 or s == n else (4.0 if s % 2 == 1 else 2.0)
        acc += point_level(packed, grid, indptr, indices, ax + t * dx, ay + t * dy) * w
        if length + scale * acc > limit * (1.0 + 1e-9):  # clearly past it, whatever the rounding
            return math.inf
    return length + lam * length * acc / (3.0 * n)


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
    pts, lam, packed, grid, indptr, indices, check, cpacked, boxes, fraction, spacing, sampling
):  # fmt: skip
    """``shortcut_kept`` compiled: from each kept point the farthest candidate first, and only until one passes."""
    n = pts.shape[0]
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
            sampling,
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
                packed,
                grid,
                indptr,
                indices,
                pts[i, 0],
                pts[i, 1],
                pts[j, 0],
                pts[j, 1],
                lam,
                sampling,
                limit,
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
            sample_spacing(field),
        )
        return out
    return _shortcut_kept_numpy(field, pts, lam, cores)


@numba.njit(cache=True, nogil=True)
def _chunked_kept(  # type: ignore[no-untyped-def]
    pts, prefix, lam, packed, growing, sampling, cpacked, boxes, fraction, spacing, edges, offsets, circles, zboxes, margin
):  # fmt: skip
    """``_shortcut_kept_numpy`` compiled, for a field with no cull index: the same chunks, counts and tests.

    A chunk's candidates are priced on the interval count its longest needs
    (``segment_costs``' rule), each sample's level by ``kernels.point_level``
    at the point ``numpy.linspace`` gives; a candidate's clearance is the
    zones' exact test (``zone_kernels.first_hit``), then the cores' sampling
    (``_clear``).  With ``growing`` (no threat's weight below zero, and
    ``lam >= 0``) a candidate's sum stops once it is past its limit.
    """
    n = pts.shape[0]
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    m = 1
    i = 0
    seg = np.empty((2, 2))
    while i < n - 1:
        best = i + 1
        ax, ay = pts[i, 0], pts[i, 1]
        for top in range(min(n - 1, i + _WINDOW), i + 1, -_CHUNK):
            low = max(i + 1, top - _CHUNK)
            longest = 0.0
            for j in range(top, low, -1):
                longest = max(longest, math.hypot(pts[j, 0] - ax, pts[j, 1] - ay))
            k = _intervals(longest, sampling)
            step = 1.0 / k
            for j in range(top, low, -1):
                dx, dy = pts[j, 0] - ax, pts[j, 1] - ay
                length = math.hypot(dx, dy)
                limit = (prefix[j] - prefix[i]) * (1.0 + 1e-12)
                acc = 0.0
                for r in range(k + 1):
                    t = 1.0 if r == k else r * step
                    w = 1.0 if r == 0 or r == k else (4.0 if r % 2 == 1 else 2.0)
                    acc += kernels.point_level(packed, ax + t * dx, ay + t * dy) * w
                    # no term is negative and rounding is monotone: past the limit now, past it in the end
                    if growing and length + lam * length * acc / (3.0 * k) > limit:
                        break
                if not length + lam * length * acc / (3.0 * k) <= limit:
                    continue
                if zboxes.shape[0]:  # a zone in force (a circle has no edges)
                    seg[0, 0], seg[0, 1], seg[1, 0], seg[1, 1] = ax, ay, pts[j, 0], pts[j, 1]
                    if zone_kernels.first_hit(edges, offsets, circles, zboxes, seg, margin)[1] >= 0:
                        continue
                if cpacked.shape[0] and not _clear(
                    cpacked, boxes, fraction, ax, ay, pts[j, 0], pts[j, 1], spacing
                ):
                    continue
                best = j
                break
            if best > i + 1:
                break
        keep[m] = best
        m += 1
        i = best
    return keep[:m].copy()


def _shortcut_kept_numpy(
    field: ThreatField, pts: np.ndarray, lam: float, cores: Cores | None, compiled: bool = True
) -> np.ndarray:
    """``shortcut_kept`` with every candidate of a window evaluated at once (any field, zones included).

    Without a cull index (and with named zones) the same loop runs compiled
    (``_chunked_kept``) unless ``compiled`` is false.
    """
    spacing = sample_spacing(field)
    seg = segment_costs(field, pts[:-1], pts[1:], lam, spacing)
    prefix = np.concatenate([[0.0], np.cumsum(seg)])
    if compiled and index_of(field) is None and (cores is None or all(cores.zones.ids)):
        return _chunked(field, pts, prefix, lam, cores, spacing)
    keep = [0]
    i = 0
    n = len(pts)
    while i < n - 1:
        best = i + 1
        # farthest first, a chunk at a time, until one passes: the same pick as the whole window's
        for top in range(min(n - 1, i + _WINDOW), i + 1, -_CHUNK):
            js = np.arange(top, max(i + 1, top - _CHUNK), -1)
            direct = segment_costs(field, np.repeat(pts[i : i + 1], len(js), axis=0), pts[js], lam, spacing)
            ok = direct <= (prefix[js] - prefix[i]) * (1.0 + 1e-12)
            for j in js[ok]:
                if cores is None or _segment_clear(cores, pts[[i, j]]):
                    best = int(j)
                    break
            if best > i + 1:
                break
        keep.append(best)
        i = best
    return np.array(keep)


def _chunked(
    field: ThreatField, pts: np.ndarray, prefix: np.ndarray, lam: float, cores: Cores | None, sampling: float
) -> np.ndarray:
    """``_chunked_kept`` on ``field``'s rows and ``cores``' (the zones' and the threat cores')."""
    none = np.zeros((0, 4))
    zones = cores.zones if cores is not None else None
    check = cores is not None and len(cores.packed) > 0
    out: np.ndarray = _chunked_kept(
        np.ascontiguousarray(pts, dtype=np.float64),
        np.ascontiguousarray(prefix, dtype=np.float64),
        float(lam),
        np.ascontiguousarray(field.packed),
        bool(lam >= 0 and (field.packed[:, kernels.SCALE] >= 0).all()),
        float(sampling),
        np.ascontiguousarray(cores.packed)
        if check and cores is not None
        else np.zeros((0, len(kernels.PACKED_COLUMNS))),
        np.ascontiguousarray(cores.boxes) if check and cores is not None else none,
        float(cores.fraction) if cores is not None else 1.0,
        float(cores.min_spread_m / 4.0) if cores is not None else math.inf,
        zones.edges if zones else none,
        zones.offsets if zones else np.zeros(1, dtype=np.int64),
        zones.circles if zones else np.zeros((0, 3)),
        zones.boxes if zones else none,
        float(cores.zone_margin_m) if cores is not None else 0.0,
    )
    return out


def _segment_clear(cores: Cores, seg: np.ndarray) -> bool:
    """``not cores.first_hit(seg)`` for one segment: the zones exactly, then the cores compiled (``_clear``).

    The same verdict, sooner: a segment that touches a zone is answered by
    the zone, and the cores are sampled as ``Cores.densify`` samples them.
    """
    if cores.zones:
        where, zone = cores.zones.first_hit(seg, cores.zone_margin_m)
        if where >= 0:
            return not zone and not cores.first_hit(seg)  # a zone with no name: as first_hit words it
    if not len(cores.packed):
        return True
    h = cores.min_spread_m / 4.0
    (ax, ay), (bx, by) = seg.tolist()
    return bool(_clear(cores.packed, cores.boxes, float(cores.fraction), ax, ay, bx, by, float(h)))


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
