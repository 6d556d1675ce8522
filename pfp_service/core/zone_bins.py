"""A zone set's boxes binned on a grid: a point's zones within a short reach without looking at every zone.

``ZoneSet.contains`` asks, per point, whether any zone lies within a few
metres (``zone_kernels.signed_many`` with a finite reach).  That kernel looks
at every zone's box for every point: over a terrain's hundreds of slope
barriers, a foresight's escape rays spent most of their time there
(BENCHMARKS.md, "Slope barriers binned").  ``Bins`` lists, for each cell of a
grid over the zones' boxes, the zones whose box meets it; ``signed``
then measures a point against the zones in the cells its reach square meets,
in the set's order, with the very test and arithmetic ``signed_many`` applies
to each zone.  A zone out of those cells has a box farther than the reach,
which ``signed_many`` skips too, so the answer is the same to the bit
(``tests/unit/test_zone_bins.py``; the order matters inside overlapping
zones, where the first one's depth is the answer).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from pfp_service.core import zone_kernels
from pfp_service.core.zone_kernels import _zone_signed, point_zone

__all__ = ["BINNED_FROM", "MAX_ENTRIES", "Bins", "bins_of", "signed"]

BINNED_FROM = 16  # zones in a set from which its points are measured through bins
MAX_SIDE = 256  # cells a side at most
MAX_ENTRIES = 1 << 20  # zones listed over all cells at most (8 MB); past it, every zone's box as before
FAR_M = 1e15  # a point or reach past this has no cell a whole number can name: every zone's box, as before


@dataclass(frozen=True, slots=True)
class Bins:
    """Cell ``(i, j)`` (``j * nx + i``) holds ``ids[starts[c]:starts[c + 1]]``, the zones whose box meets it."""

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    starts: np.ndarray
    ids: np.ndarray


def bins_of(boxes: np.ndarray) -> Bins | None:
    """The zones of ``boxes`` (``(n, 4)``: x0, y0, x1, y1) binned on cells about the size of a typical box;
    ``None`` when that would list more than ``MAX_ENTRIES`` (zones as large as the grid: each point's look
    would be most of them anyway)."""
    lo = boxes[:, :2].min(axis=0)
    hi = boxes[:, 2:].max(axis=0)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1], 1.0))
    sides = np.maximum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1])
    cell = max(float(np.median(sides)), span / MAX_SIDE, 1.0)
    nx = int(min(MAX_SIDE, math.floor((hi[0] - lo[0]) / cell) + 1))
    ny = int(min(MAX_SIDE, math.floor((hi[1] - lo[1]) / cell) + 1))
    i0 = np.clip(np.floor((boxes[:, 0] - lo[0]) / cell), 0, nx - 1).astype(np.int64)
    i1 = np.clip(np.floor((boxes[:, 2] - lo[0]) / cell), 0, nx - 1).astype(np.int64)
    j0 = np.clip(np.floor((boxes[:, 1] - lo[1]) / cell), 0, ny - 1).astype(np.int64)
    j1 = np.clip(np.floor((boxes[:, 3] - lo[1]) / cell), 0, ny - 1).astype(np.int64)
    w = i1 - i0 + 1
    count = w * (j1 - j0 + 1)  # cells each zone's box meets
    if int(count.sum()) > MAX_ENTRIES:
        return None
    zone = np.repeat(np.arange(len(boxes), dtype=np.int64), count)
    at = np.arange(len(zone), dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)  # within its block
    flat = (j0[zone] + at // w[zone]) * nx + i0[zone] + at % w[zone]
    order = np.lexsort((zone, flat))  # by cell, each cell's zones in the set's order
    starts = np.searchsorted(flat[order], np.arange(nx * ny + 1)).astype(np.int64)
    return Bins(float(lo[0]), float(lo[1]), cell, nx, ny, starts, zone[order])


def signed(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    bins: Bins | None,
    pts: np.ndarray,
    out: np.ndarray,
    reach: float,
) -> None:
    """``zone_kernels.signed_many(..., pts, out, reach)``: through ``bins`` when there are bins and ``reach`` is short."""
    if bins is None or not reach < FAR_M:  # an unbounded reach (or NaN): every zone's box, as before
        zone_kernels.signed_many(edges, offsets, circles, boxes, pts, out, float(reach))
        return
    _signed_binned(
        edges, offsets, circles, boxes, pts, out, float(reach), bins.x0, bins.y0, bins.cell, bins.nx, bins.ny,
        bins.starts, bins.ids,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def _cells(v: float, r: float, origin: float, cell: float, n: int) -> tuple[int, int]:
    """The cells along one axis that ``[v - r, v + r]`` meets, clamped to the grid (a zone's box is inside it)."""
    a = min(max(math.floor((v - r - origin) / cell), 0.0), n - 1.0)
    b = min(max(math.floor((v + r - origin) / cell), 0.0), n - 1.0)
    return int(a), int(b)


@numba.njit(cache=True, nogil=True)
def _signed_binned(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    pts: np.ndarray,
    out: np.ndarray,
    reach: float,
    x0: float,
    y0: float,
    cell: float,
    nx: int,
    ny: int,
    starts: np.ndarray,
    ids: np.ndarray,
) -> None:
    seen = np.full(boxes.shape[0], -1, dtype=np.int64)  # the point that last took each zone
    buf = np.empty(boxes.shape[0], dtype=np.int64)
    for p in range(pts.shape[0]):
        x = pts[p, 0]
        y = pts[p, 1]
        if not (abs(x) < FAR_M and abs(y) < FAR_M):  # no cell to look in (NaN, inf): every zone, as before
            out[p] = point_zone(edges, offsets, circles, boxes, x, y, reach)[0]
            continue
        i0, i1 = _cells(x, reach, x0, cell, nx)
        j0, j1 = _cells(y, reach, y0, cell, ny)
        n = 0
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                c = j * nx + i
                for k in range(starts[c], starts[c + 1]):
                    z = ids[k]
                    if seen[z] != p:
                        seen[z] = p
                        buf[n] = z
                        n += 1
        # in the set's order, as ``point_zone``: inside overlapping zones, the first one's depth is the answer
        took = np.sort(buf[:n])
        best = math.inf
        for z in took:
            bx = max(boxes[z, 0] - x, 0.0, x - boxes[z, 2])
            by = max(boxes[z, 1] - y, 0.0, y - boxes[z, 3])
            if math.hypot(bx, by) > min(best, reach):
                continue  # as ``point_zone``: farther than the reach, or than the best so far
            sd = _zone_signed(edges, offsets, circles, z, x, y)
            if sd < best:
                best = sd
        out[p] = best
