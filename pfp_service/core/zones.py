"""Keep-out zones: areas a unit must never enter, their geometry, and the compiled tests on them.

A ``Zone`` is a polygon (an outer ring and optional holes) or a circle, in
local metres, with an id and a ``kind`` (only ``keep_out`` so far).  Shapely
(GEOS) checks that a polygon is valid -- closed, not self-intersecting, holes
inside the shell -- and gives exact areas and distances for reports; the hot
paths (the step rule, the descent's barrier, the route grids) use the packed
form of a ``ZoneSet`` and the numba kernels below, which are exact for
polygons and circles (no sampling: a segment's first contact with a zone is
solved, so a thin zone is never stepped over).

A zone is *closed*: a point on its boundary is in it, and so is one within
``TOUCH_M`` (a nanometre) of it, so that rounding never turns a touch into a
miss.  ``track_enters`` and every check use that one rule.

How the live side hands zones to the engine: build ``ZoneSet(zones)`` from
the zones in force (the wire's ``ZoneUpdate.to_zone`` turns one into a ``Zone``:
the core never imports the wire) and give it to the field, ``field.with_zones(zone_set)``: a
``ThreatField`` carries its ``ZoneSet`` (``field.zones``), so everything that
takes a field -- the stepper, previews, escapes, routes, metrics -- sees the
zones with no other argument.  A field is immutable; a zone put, moved,
deleted or expired builds a new ``ZoneSet`` and a new field, as a threat
change does.  A TTL lives on the wire and in the world, not here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
import shapely
from shapely.geometry import Point as _SPoint
from shapely.geometry import Polygon as _SPolygon
from shapely.validation import explain_validity

__all__ = [
    "KINDS",
    "MAX_RINGS",
    "MAX_VERTICES",
    "TOUCH_M",
    "Zone",
    "ZoneSet",
    "point_zone",
    "segment_hit",
    "track_enters",
]

KINDS = ("keep_out",)
MAX_VERTICES = 4096  # per zone, over all its rings
MAX_RINGS = 64  # holes plus the shell
TOUCH_M = 1e-9  # closer to a zone than this is in it
SEARCH_MARGIN_REL = 1e-5  # the route searches keep this share of the largest zone's extent clear

Ring = tuple[tuple[float, float], ...]


def _open_ring(points: Sequence[Sequence[float]], what: str) -> Ring:
    """``points`` as a ring without its closing repeat; refuses what is not a ring of finite points."""
    ring = tuple((float(p[0]), float(p[1])) for p in points)
    if len(ring) >= 2 and ring[0] == ring[-1]:
        ring = ring[:-1]
    if not all(math.isfinite(v) for p in ring for v in p):
        raise ValueError(f"{what}: every vertex must be finite")
    if len(set(ring)) < 3:
        raise ValueError(f"{what}: a ring needs at least 3 distinct vertices, got {len(set(ring))}")
    return ring


@dataclass(frozen=True, slots=True)
class Zone:
    """One keep-out zone, in local metres (x east, y north).

    Attributes:
        id: the zone's name (its key chunk on the wire).
        shell: a polygon's outer ring, without the closing repeat.
        holes: a polygon's inner rings (areas inside the shell that are not in the zone).
        centre: a circle's centre; ``None`` for a polygon.
        radius_m: a circle's radius; 0 for a polygon.
        kind: what the zone means; ``keep_out``: no unit enters it.

    Raises:
        ValueError: neither or both of a polygon and a circle, a ring with fewer
            than 3 distinct vertices, a self-intersecting ring or a hole outside
            the shell (shapely's reason), a non-finite number, a radius <= 0.
    """

    id: str
    shell: Ring = ()
    holes: tuple[Ring, ...] = ()
    centre: tuple[float, float] | None = None
    radius_m: float = 0.0
    kind: str = "keep_out"
    geometry: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"zone {self.id!r}: kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if self.centre is not None:
            if self.shell or self.holes:
                raise ValueError(f"zone {self.id!r}: a zone is a polygon or a circle, not both")
            cx, cy = self.centre
            if not (math.isfinite(cx) and math.isfinite(cy)):
                raise ValueError(f"zone {self.id!r}: centre must be finite")
            if not (math.isfinite(self.radius_m) and self.radius_m > 0.0):
                raise ValueError(f"zone {self.id!r}: radius_m must be > 0, got {self.radius_m!r}")
            geom = _SPoint(cx, cy).buffer(self.radius_m, quad_segs=32)
        else:
            if not self.shell:
                raise ValueError(f"zone {self.id!r}: a zone needs a polygon (shell) or a circle (centre)")
            shell = _open_ring(self.shell, f"zone {self.id!r} shell")
            holes = tuple(_open_ring(h, f"zone {self.id!r} holes[{i}]") for i, h in enumerate(self.holes))
            object.__setattr__(self, "shell", shell)
            object.__setattr__(self, "holes", holes)
            if 1 + len(holes) > MAX_RINGS:
                raise ValueError(f"zone {self.id!r}: more than {MAX_RINGS} rings")
            if len(shell) + sum(len(h) for h in holes) > MAX_VERTICES:
                raise ValueError(f"zone {self.id!r}: more than {MAX_VERTICES} vertices")
            geom = _SPolygon(shell, holes)
            if not geom.is_valid:
                raise ValueError(f"zone {self.id!r}: not a valid polygon: {explain_validity(geom)}")
            if geom.area <= 0.0:
                raise ValueError(f"zone {self.id!r}: the polygon has no area")
        shapely.prepare(geom)
        object.__setattr__(self, "geometry", geom)

    @classmethod
    def circle(cls, id: str, centre: Sequence[float], radius_m: float, kind: str = "keep_out") -> Zone:
        """A circular zone."""
        return cls(id=id, centre=(float(centre[0]), float(centre[1])), radius_m=float(radius_m), kind=kind)

    @classmethod
    def polygon(
        cls,
        id: str,
        shell: Sequence[Sequence[float]],
        holes: Sequence[Sequence[Sequence[float]]] = (),
        kind: str = "keep_out",
    ) -> Zone:
        """A polygonal zone (rings closed or not)."""
        return cls(
            id=id,
            shell=tuple((float(p[0]), float(p[1])) for p in shell),
            holes=tuple(tuple((float(p[0]), float(p[1])) for p in h) for h in holes),
            kind=kind,
        )

    @property
    def is_circle(self) -> bool:
        return self.centre is not None

    def rings(self) -> tuple[Ring, ...]:
        """The shell then the holes (empty for a circle)."""
        return (self.shell, *self.holes) if self.shell else ()

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)``: exact for a circle and a polygon."""
        if self.centre is not None:
            cx, cy = self.centre
            r = self.radius_m
            return cx - r, cy - r, cx + r, cy + r
        xs = [p[0] for p in self.shell]
        ys = [p[1] for p in self.shell]
        return min(xs), min(ys), max(xs), max(ys)

    def contains(self, x: float, y: float) -> bool:
        """Whether ``(x, y)`` lies in the zone, its boundary included."""
        return self.signed_distance(x, y) <= TOUCH_M

    def signed_distance(self, x: float, y: float) -> float:
        """Metres from ``(x, y)`` to the zone's boundary: > 0 outside, <= 0 inside (the depth)."""
        return float(ZoneSet((self,)).signed_distance(np.array([[x, y]]))[0])

    def distance(self, x: float, y: float) -> float:
        """Metres from ``(x, y)`` to the zone; 0 inside it."""
        return max(0.0, self.signed_distance(x, y))

    def area_m2(self) -> float:
        """The zone's area (a circle's exactly)."""
        if self.centre is not None:
            return math.pi * self.radius_m**2
        return float(self.geometry.area)


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
def _signed_many(
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    pts: np.ndarray,
    out: np.ndarray,
) -> None:
    for i in range(pts.shape[0]):
        out[i] = point_zone(edges, offsets, circles, boxes, pts[i, 0], pts[i, 1], math.inf)[0]


@numba.njit(cache=True, nogil=True)
def _nearest_many(
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
def _first_hit(
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
def _segment_hits(
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
def _raster(
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


class ZoneSet:
    """The zones in force, packed for the kernels.  Immutable; empty is the common case.

    Args:
        zones: the zones; ids must be unique.

    Raises:
        ValueError: a repeated id.
    """

    __slots__ = ("__weakref__", "boxes", "circles", "edges", "ids", "offsets", "search_margin_m", "zones")

    def __init__(self, zones: Iterable[Zone] = ()) -> None:
        self.zones: tuple[Zone, ...] = tuple(zones)
        self.ids: tuple[str, ...] = tuple(z.id for z in self.zones)
        if len(set(self.ids)) != len(self.ids):
            seen: set[str] = set()
            dup = next(i for i in self.ids if i in seen or seen.add(i))  # type: ignore[func-returns-value]
            raise ValueError(f"zone {dup!r}: the id is given twice")
        rows: list[tuple[float, float, float, float]] = []
        offsets = [0]
        circles = np.zeros((len(self.zones), 3))
        boxes = np.zeros((len(self.zones), 4))
        for z, zone in enumerate(self.zones):
            boxes[z] = zone.bounds()
            if zone.centre is not None:
                circles[z] = (zone.centre[0], zone.centre[1], zone.radius_m)
            for ring in zone.rings():
                for a, b in zip(ring, ring[1:] + ring[:1], strict=True):
                    rows.append((a[0], a[1], b[0], b[1]))
            offsets.append(len(rows))
        self.edges = np.array(rows, dtype=np.float64).reshape(-1, 4)
        self.offsets = np.array(offsets, dtype=np.int64)
        self.circles = circles
        self.boxes = boxes
        # the route searches' clearance from a zone, as the 0.48 core is theirs: rounding never
        # makes a route that grazes a corner touch it (a millimetre for a 100 m zone)
        extent = float(np.max(boxes[:, 2:] - boxes[:, :2])) if len(boxes) else 0.0
        scale = float(np.max(np.abs(boxes))) if len(boxes) else 0.0
        self.search_margin_m = SEARCH_MARGIN_REL * max(extent, 1.0) + 1e-9 * scale

    def __len__(self) -> int:
        return len(self.zones)

    def __bool__(self) -> bool:
        return bool(self.zones)

    def __iter__(self) -> Any:
        return iter(self.zones)

    def packed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(edges, offsets, circles, boxes)``: what the kernels take."""
        return self.edges, self.offsets, self.circles, self.boxes

    def get(self, zone_id: str) -> Zone | None:
        for z in self.zones:
            if z.id == zone_id:
                return z
        return None

    def plus(self, extra: Iterable[Zone], replacing: Iterable[str] = ()) -> ZoneSet:
        """These zones without those whose id is in ``replacing`` or in ``extra``, then ``extra``."""
        extra = tuple(extra)
        drop = set(replacing) | {z.id for z in extra}
        return ZoneSet((*(z for z in self.zones if z.id not in drop), *extra))

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Per point of ``(N, 2)``, metres to the nearest zone (<= 0 inside; ``inf`` with no zones)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.full(len(pts), math.inf)
        if self.zones and len(pts):
            _signed_many(self.edges, self.offsets, self.circles, self.boxes, pts, out)
        return out

    def nearest_many(self, points: np.ndarray) -> tuple[np.ndarray, list[str]]:
        """Per point, the signed distance to the nearest zone and its id (``""`` with no zones)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.full(len(pts), math.inf)
        idx = np.full(len(pts), -1, dtype=np.int64)
        if self.zones and len(pts):
            _nearest_many(self.edges, self.offsets, self.circles, self.boxes, pts, out, idx)
        return out, [self.ids[i] if i >= 0 else "" for i in idx.tolist()]

    def contains(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Boolean mask: which points lie in some zone (boundary included), or within ``margin_m`` of one."""
        return self.signed_distance(points) <= max(TOUCH_M, margin_m)

    def zone_at(self, x: float, y: float) -> str:
        """The id of the zone holding ``(x, y)`` (the deepest), or ``""``."""
        if not self.zones:
            return ""
        sd, z, _, _ = point_zone(self.edges, self.offsets, self.circles, self.boxes, x, y, math.inf)
        return self.ids[z] if sd <= TOUCH_M else ""

    def nearest(self, x: float, y: float) -> tuple[float, str, tuple[float, float]]:
        """``(signed distance, zone id, unit gradient)`` of the nearest zone (``inf, "", (0, 0)`` with none)."""
        if not self.zones:
            return math.inf, "", (0.0, 0.0)
        sd, z, gx, gy = point_zone(self.edges, self.offsets, self.circles, self.boxes, x, y, math.inf)
        return sd, self.ids[z], (gx, gy)

    def first_hit(self, path: np.ndarray, margin_m: float = 0.0) -> tuple[int, str]:
        """The first segment index of polyline ``path`` that touches a zone and the zone; ``(-1, "")``.

        Exact (each segment is solved against every edge and circle), so no
        zone, however thin, is passed over between two points.  With
        ``margin_m``, a segment that comes that close to a zone counts.
        """
        pts = np.ascontiguousarray(path, dtype=np.float64).reshape(-1, 2)
        if not self.zones or not len(pts):
            return -1, ""
        i, z = _first_hit(self.edges, self.offsets, self.circles, self.boxes, pts, margin_m)
        return (int(i), self.ids[z]) if z >= 0 else (-1, "")

    def first_contact(self, path: np.ndarray, margin_m: float = 0.0) -> tuple[int, float, str]:
        """``first_hit`` with where on its segment: ``(segment, fraction along it, zone id)``; ``(-1, 0, "")``."""
        seg, zid = self.first_hit(path, margin_m)
        if seg < 0:
            return -1, 0.0, ""
        pts = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        if len(pts) < 2:
            return 0, 0.0, zid
        a, b = pts[seg], pts[seg + 1]
        t, _ = segment_hit(self.edges, self.offsets, self.circles, self.boxes, a[0], a[1], b[0], b[1])
        return seg, max(float(t), 0.0), zid  # within the margin only: where the segment starts

    def segment_hits(self, path: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Per segment of the polyline ``path``: does it touch a zone (exactly), or come within ``margin_m``?"""
        pts = np.ascontiguousarray(path, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(max(len(pts) - 1, 0), dtype=np.bool_)
        if self.zones and len(pts) > 1:
            _segment_hits(self.edges, self.offsets, self.circles, self.boxes, pts, out, margin_m)
        return out

    def way_out(self, x: float, y: float, clear_m: float) -> tuple[float, float] | None:
        """From ``(x, y)`` in a zone, the point ``clear_m`` past the nearest edge (the shortest way out).

        ``None`` when ``(x, y)`` is in no zone, or the way out ends in another zone.
        """
        sd, _zid, (gx, gy) = self.nearest(x, y)
        if sd > TOUCH_M:
            return None
        if gx == 0.0 and gy == 0.0:  # on an edge's ray of symmetry: any outward normal will do
            return None
        r = -sd + clear_m
        end = (x + gx * r, y + gy * r)
        return None if self.zone_at(*end) else end

    def clearance(self, path: np.ndarray) -> float:
        """The least signed distance from the polyline ``path`` to any zone (< 0: it enters one).

        Vertices by the kernels; a segment that crosses a zone between two
        vertices outside it counts as entering (``-0.0`` when no vertex is inside).
        """
        pts = np.ascontiguousarray(path, dtype=np.float64).reshape(-1, 2)
        if not self.zones or not len(pts):
            return math.inf
        least = float(self.signed_distance(pts).min())
        if least > 0.0 and len(pts) > 1:
            # a segment's closest approach lies between its vertices: ask GEOS, once
            line = shapely.LineString(pts)
            least = min(least, min(float(z.geometry.distance(line)) for z in self.zones))
            if self.first_hit(pts)[0] >= 0:
                least = min(least, 0.0)
        return least

    def raster(
        self,
        origin: tuple[float, float],
        cell_m: float,
        shape: tuple[int, int],
        margin_m: float | None = None,
    ) -> np.ndarray:
        """Boolean ``shape`` grid: node ``origin + (i, k) cell_m`` lies within ``margin_m`` of a zone.

        The default margin, ``cell_m * sqrt(2) / 2`` plus a hair, blocks every
        node whose grid cell a zone touches: a straight move between two free
        neighbours (8-connected) stays inside their two cells, so it cannot
        touch a zone, however thin.
        """
        out = np.zeros(shape, dtype=np.bool_)
        if self.zones:
            m = cell_m * (math.sqrt(0.5) + 1e-6) if margin_m is None else margin_m
            _raster(
                self.edges, self.offsets, self.circles, self.boxes, float(origin[0]), float(origin[1]),
                float(cell_m), float(m), out,
            )  # fmt: skip
        return out


_EMPTY = ZoneSet()


def track_enters(
    zones: ZoneSet | Iterable[Zone], points: np.ndarray | Sequence[Sequence[float]]
) -> str | None:
    """The id of the first zone the polyline ``points`` enters (touches), or ``None``.

    Exact for every segment (``ZoneSet.first_hit``), so "densely" by construction.
    """
    zs = zones if isinstance(zones, ZoneSet) else ZoneSet(zones)
    _, zid = zs.first_hit(np.asarray(points, dtype=np.float64))
    return zid or None
