"""The compiled zone tests: a point's zone and signed distance, a segment's first hit, a raster.

``ZoneSet`` (``core.zones``) packs its zones into the arrays these kernels take and calls them;
the step rule and the route walkers call ``point_zone`` and ``segment_hit`` from their own compiled
loops.  Apart from ``zones.py`` so the zones' model (validation, shapely, the set's queries) reads
without the loops, as ``route_kernels`` stands beside ``route``.  One closeness rule for all:
within ``TOUCH_M`` of a zone is in it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "TOUCH_M",
    "first_hit",
    "nearest_many",
    "point_zone",
    "raster",
    "segment_hit",
    "segment_hits",
    "segment_near",
    "signed_many",
]

TOUCH_M = 1e-9  # closer to a zone than this is in it

# -- the compiled tests ---------------------------------------------------------
# A ``ZoneSet`` packs its zones into four arrays the kernels take:
#   edges (E, 4): every polygon ring's edges (x0, y0, x1, y1), zone by zone;
#   offsets (Z + 1,): zone z's edges are edges[offsets[z]:offsets[z + 1]];
#   circles (Z, 3): centre and radius of a circle zone (radius 0 for a polygon);
#   boxes (Z, 4): each zone's bounding box (xmin, ymin, xmax, ymax).


@numba.njit(cache=True, nogil=True, inline="always")
def _edge_distance(
    x: float, y: float, ax: float, ay: float, bx: float, by: float
) -> tuple[float, float, float]:
    """Distance from ``(x, y)`` to segment ``ab`` and the closest point on it."""
    ex = bx - ax
    ey = by - ay
    ll = ex * ex + ey * ey
    t = 0.0 if ll == 0.0 else ((x - ax) * ex + (y - ay) * ey) / ll
    t = min(1.0, max(0.0, t))
    cx = ax + t * ex
    cy = ay + t * ey
    return math.hypot(x - cx, y - cy), cx, cy


@numba.njit(cache=True, nogil=True)
def point_zone(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    x: float,
    y: float,
    reach: float,
) -> tuple[float, int, float, float]:
    """The nearest zone's signed distance at ``(x, y)``, which zone, and the distance's gradient.

    Args:
        reach: zones farther than this (by their box) are skipped; ``inf`` skips none.

    Returns:
        ``(sd, z, gx, gy)``: ``sd`` > 0 outside (metres to the zone), <= 0 inside
        (minus the depth); ``z`` the zone (-1 when none within ``reach``, then
        ``sd`` is ``inf``); ``(gx, gy)`` the unit gradient of ``sd`` (pointing
        away from the zone), zero where it is undefined.
    """
    best = math.inf
    arg = -1
    bgx = 0.0
    bgy = 0.0
    for z in range(boxes.shape[0]):
        bx = max(boxes[z, 0] - x, 0.0, x - boxes[z, 2])
        by = max(boxes[z, 1] - y, 0.0, y - boxes[z, 3])
        if math.hypot(bx, by) > min(best, reach):
            continue  # outside the box, farther than the best so far: cannot be nearer
        r = circles[z, 2]
        if r > 0.0:
            dx = x - circles[z, 0]
            dy = y - circles[z, 1]
            d = math.hypot(dx, dy)
            sd = d - r
            if sd < best:
                best = sd
                arg = z
                if d > 0.0:
                    bgx = dx / d
                    bgy = dy / d
                else:
                    bgx = 0.0
                    bgy = 0.0
            continue
        inside = False
        dmin = math.inf
        cx = x
        cy = y
        for e in range(offsets[z], offsets[z + 1]):
            ax = edges[e, 0]
            ay = edges[e, 1]
            qx = edges[e, 2]
            qy = edges[e, 3]
            if (ay > y) != (qy > y):
                xc = ax + (y - ay) * (qx - ax) / (qy - ay)
                if x < xc:
                    inside = not inside
            d, px, py = _edge_distance(x, y, ax, ay, qx, qy)
            if d < dmin:
                dmin = d
                cx = px
                cy = py
        sd = -dmin if inside else dmin
        if sd < best:
            best = sd
            arg = z
            if dmin > 0.0:
                s = -1.0 if inside else 1.0
                bgx = s * (x - cx) / dmin
                bgy = s * (y - cy) / dmin
            else:
                bgx = 0.0
                bgy = 0.0
    return best, arg, bgx, bgy


@numba.njit(cache=True, nogil=True, inline="always")
def _cross_t(x0: float, y0: float, dx: float, dy: float, ax: float, ay: float, bx: float, by: float) -> float:
    """The smallest ``t`` in [0, 1] where ``p0 + t d`` meets segment ``ab`` (closed), else -1."""
    ex = bx - ax
    ey = by - ay
    den = dx * ey - dy * ex
    wx = ax - x0
    wy = ay - y0
    if den != 0.0:
        t = (wx * ey - wy * ex) / den
        s = (wx * dy - wy * dx) / den
        if 0.0 <= t <= 1.0 and 0.0 <= s <= 1.0:
            return t
        return -1.0
    # parallel: collinear overlap only
    if wx * dy - wy * dx != 0.0:
        return -1.0
    dd = dx * dx + dy * dy
    if dd == 0.0:
        return -1.0
    ta = (wx * dx + wy * dy) / dd
    tb = ((bx - x0) * dx + (by - y0) * dy) / dd
    lo = min(ta, tb)
    hi = max(ta, tb)
    if hi < 0.0 or lo > 1.0:
        return -1.0
    return max(lo, 0.0)


@numba.njit(cache=True, nogil=True)
def _zone_signed(
    edges: np.ndarray, offsets: np.ndarray, circles: np.ndarray, z: int, x: float, y: float
) -> float:
    """Zone ``z``'s signed distance at ``(x, y)``."""
    r: float = circles[z, 2]
    if r > 0.0:
        return math.hypot(x - circles[z, 0], y - circles[z, 1]) - r
    inside = False
    dmin = math.inf
    for e in range(offsets[z], offsets[z + 1]):
        ax = edges[e, 0]
        ay = edges[e, 1]
        qx = edges[e, 2]
        qy = edges[e, 3]
        if (ay > y) != (qy > y) and x < ax + (y - ay) * (qx - ax) / (qy - ay):
            inside = not inside
        d: float = _edge_distance(x, y, ax, ay, qx, qy)[0]
        dmin = min(dmin, d)
    return -dmin if inside else dmin


@numba.njit(cache=True, nogil=True)
def segment_hit(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
) -> tuple[float, int]:
    """Where the segment ``(x0, y0) -> (x1, y1)`` first touches a zone (boundary included).

    Returns:
        ``(t, z)``: the fraction of the segment at the first contact (0 when it
        starts in a zone) and the zone; ``(-1, -1)`` when it touches none.
    """
    dx = x1 - x0
    dy = y1 - y0
    sx0 = min(x0, x1)
    sx1 = max(x0, x1)
    sy0 = min(y0, y1)
    sy1 = max(y0, y1)
    best = math.inf
    arg = -1
    for z in range(boxes.shape[0]):
        if boxes[z, 0] > sx1 or boxes[z, 2] < sx0 or boxes[z, 1] > sy1 or boxes[z, 3] < sy0:
            continue
        r = circles[z, 2]
        if r > 0.0:
            fx = x0 - circles[z, 0]
            fy = y0 - circles[z, 1]
            c = fx * fx + fy * fy - r * r
            if math.hypot(fx, fy) - r <= TOUCH_M:
                return 0.0, z
            a = dx * dx + dy * dy
            b = fx * dx + fy * dy
            disc = b * b - a * c
            if a == 0.0 or disc < 0.0 or b >= 0.0:
                continue
            t = (-b - math.sqrt(disc)) / a
            if 0.0 <= t <= 1.0 and t < best:
                best = t
                arg = z
            continue
        if _zone_signed(edges, offsets, circles, z, x0, y0) <= TOUCH_M:
            return 0.0, z  # starts in the zone or on its boundary
        for e in range(offsets[z], offsets[z + 1]):
            t = _cross_t(x0, y0, dx, dy, edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3])
            if t >= 0.0 and t < best:
                best = t
                arg = z
    if arg < 0:  # no crossing: the end may still touch (a crossing lost to rounding)
        for z in range(boxes.shape[0]):
            if boxes[z, 0] - x1 > TOUCH_M or x1 - boxes[z, 2] > TOUCH_M:
                continue
            if boxes[z, 1] - y1 > TOUCH_M or y1 - boxes[z, 3] > TOUCH_M:
                continue
            if _zone_signed(edges, offsets, circles, z, x1, y1) <= TOUCH_M:
                return 1.0, z
        return -1.0, -1
    return best, arg


@numba.njit(cache=True, nogil=True)
def signed_many(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    pts: np.ndarray,
    out: np.ndarray,
    reach: float,
) -> None:
    for i in range(pts.shape[0]):
        out[i] = point_zone(edges, offsets, circles, boxes, pts[i, 0], pts[i, 1], reach)[0]


@numba.njit(cache=True, nogil=True)
def nearest_many(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    pts: np.ndarray,
    out: np.ndarray,
    idx: np.ndarray,
) -> None:
    for i in range(pts.shape[0]):
        sd, z, _, _ = point_zone(edges, offsets, circles, boxes, pts[i, 0], pts[i, 1], math.inf)
        out[i] = sd
        idx[i] = z


@numba.njit(cache=True, nogil=True)
def _point_segment(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    return _edge_distance(px, py, ax, ay, bx, by)[0]


@numba.njit(cache=True, nogil=True)
def segment_near(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    margin: float,
) -> int:
    """The zone the segment comes within ``margin`` of (or touches), or -1; ``margin <= 0``: ``segment_hit``."""
    if margin <= 0.0:
        return segment_hit(edges, offsets, circles, boxes, x0, y0, x1, y1)[1]
    sx0 = min(x0, x1) - margin
    sx1 = max(x0, x1) + margin
    sy0 = min(y0, y1) - margin
    sy1 = max(y0, y1) + margin
    dx = x1 - x0
    dy = y1 - y0
    for z in range(boxes.shape[0]):
        if boxes[z, 0] > sx1 or boxes[z, 2] < sx0 or boxes[z, 1] > sy1 or boxes[z, 3] < sy0:
            continue
        r = circles[z, 2]
        if r > 0.0:
            if _point_segment(circles[z, 0], circles[z, 1], x0, y0, x1, y1) <= r + margin:
                return z
            continue
        if _zone_signed(edges, offsets, circles, z, x0, y0) <= margin:
            return z
        for e in range(offsets[z], offsets[z + 1]):
            ax = edges[e, 0]
            ay = edges[e, 1]
            bx = edges[e, 2]
            by = edges[e, 3]
            if _cross_t(x0, y0, dx, dy, ax, ay, bx, by) >= 0.0:
                return z
            d = min(
                _point_segment(x0, y0, ax, ay, bx, by),
                _point_segment(x1, y1, ax, ay, bx, by),
                _point_segment(ax, ay, x0, y0, x1, y1),
                _point_segment(bx, by, x0, y0, x1, y1),
            )
            if d <= margin:
                return z
    return -1


@numba.njit(cache=True, nogil=True)
def first_hit(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    pts: np.ndarray,
    margin: float,
) -> tuple[int, int]:
    """The first segment of the polyline ``pts`` within ``margin`` of a zone (touching it at 0), and the zone."""
    n = pts.shape[0]
    if n == 1:
        sd, z, _, _ = point_zone(edges, offsets, circles, boxes, pts[0, 0], pts[0, 1], max(margin, 0.0))
        return (0, z) if z >= 0 and sd <= max(TOUCH_M, margin) else (-1, -1)
    for i in range(n - 1):
        z = segment_near(
            edges, offsets, circles, boxes, pts[i, 0], pts[i, 1], pts[i + 1, 0], pts[i + 1, 1], margin
        )
        if z >= 0:
            return i, z
    return -1, -1


@numba.njit(cache=True, nogil=True)
def segment_hits(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    pts: np.ndarray,
    out: np.ndarray,
    margin: float,
) -> None:
    """``out[i]``: segment ``pts[i] -> pts[i + 1]`` touches a zone (comes within ``margin`` of one)."""
    for i in range(pts.shape[0] - 1):
        out[i] = (
            segment_near(
                edges, offsets, circles, boxes, pts[i, 0], pts[i, 1], pts[i + 1, 0], pts[i + 1, 1], margin
            )
            >= 0
        )


@numba.njit(cache=True, nogil=True)
def raster(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    x0: float,
    y0: float,
    h: float,
    margin: float,
    out: np.ndarray,
) -> None:
    """``out[i, k]`` |= node ``(x0 + i h, y0 + k h)`` is within ``margin`` of a zone (or in it).

    By rows, not node by node: a circle is a disc of radius ``r + margin``; a
    polygon is its interior (each row filled between the sorted crossings of
    its edges, holes by parity) and a strip of ``margin`` along each edge.
    """
    nx, ny = out.shape
    xs = np.empty(max(edges.shape[0], 1))
    for z in range(boxes.shape[0]):
        r = circles[z, 2]
        if r > 0.0:
            big = r + margin
            cx = circles[z, 0]
            cy = circles[z, 1]
            k0 = max(0, math.ceil((cy - big - y0) / h))
            k1 = min(ny - 1, math.floor((cy + big - y0) / h))
            for k in range(k0, k1 + 1):
                dy = y0 + k * h - cy
                w = math.sqrt(max(big * big - dy * dy, 0.0))
                i0 = max(0, math.ceil((cx - w - x0) / h))
                i1 = min(nx - 1, math.floor((cx + w - x0) / h))
                for i in range(i0, i1 + 1):
                    out[i, k] = True
            continue
        for e in range(offsets[z], offsets[z + 1]):  # the strip along each edge
            ax = edges[e, 0]
            ay = edges[e, 1]
            bx = edges[e, 2]
            by = edges[e, 3]
            i0 = max(0, math.floor((min(ax, bx) - margin - x0) / h))
            i1 = min(nx - 1, math.ceil((max(ax, bx) + margin - x0) / h))
            k0 = max(0, math.floor((min(ay, by) - margin - y0) / h))
            k1 = min(ny - 1, math.ceil((max(ay, by) + margin - y0) / h))
            for i in range(i0, i1 + 1):
                x = x0 + i * h
                for k in range(k0, k1 + 1):
                    if not out[i, k] and _edge_distance(x, y0 + k * h, ax, ay, bx, by)[0] <= margin:
                        out[i, k] = True
        k0 = max(0, math.floor((boxes[z, 1] - y0) / h))  # the interior, row by row
        k1 = min(ny - 1, math.ceil((boxes[z, 3] - y0) / h))
        for k in range(k0, k1 + 1):
            y = y0 + k * h
            n = 0
            for e in range(offsets[z], offsets[z + 1]):
                ay = edges[e, 1]
                by = edges[e, 3]
                if (ay > y) != (by > y):
                    ax = edges[e, 0]
                    xs[n] = ax + (y - ay) * (edges[e, 2] - ax) / (by - ay)
                    n += 1
            row = np.sort(xs[:n])
            for j in range(0, n - 1, 2):
                i0 = max(0, math.ceil((row[j] - x0) / h))
                i1 = min(nx - 1, math.floor((row[j + 1] - x0) / h))
                for i in range(i0, i1 + 1):
                    out[i, k] = True
