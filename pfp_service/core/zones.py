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
the zones in force (``world.translate.zone`` turns a wire ``ZoneUpdate`` into a ``Zone``:
the core never imports the wire) and give it to the field, ``field.with_zones(zone_set)``: a
``ThreatField`` carries its ``ZoneSet`` (``field.zones``), so everything that
takes a field -- the stepper, previews, escapes, routes, metrics -- sees the
zones with no other argument.  A field is immutable; a zone put, moved,
deleted or expired builds a new ``ZoneSet`` and a new field, as a threat
change does.  A TTL lives on the wire and in the world, not here.
"""

from __future__ import annotations

import math
import pickle
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Point as _SPoint
from shapely.geometry import Polygon as _SPolygon
from shapely.validation import explain_validity

from pfp_service.core import zone_bins, zone_kernels
from pfp_service.core.zone_kernels import TOUCH_M, point_zone, segment_hit

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


_UNPICKLED: dict[bytes, ZoneSet] = {}  # the last few sets unpickled in this process, by their bytes
_UNPICKLED_KEPT = 4


def _unpickled(data: bytes) -> ZoneSet:
    """The ``ZoneSet`` pickled as ``data`` (``ZoneSet.__reduce__``): the same object again while it is among the
    last ``_UNPICKLED_KEPT`` (a worker is sent the set in force with every chunk; a bytes key hashes once)."""
    got = _UNPICKLED.get(data)
    if got is not None:
        return got
    zs = ZoneSet.__new__(ZoneSet)
    (zs.zones, zs.ids, zs.edges, zs.offsets, zs.circles, zs.boxes, zs.search_margin_m) = pickle.loads(data)
    zs._pickled, zs._bins = data, None
    while len(_UNPICKLED) >= _UNPICKLED_KEPT:
        del _UNPICKLED[next(iter(_UNPICKLED))]
    _UNPICKLED[data] = zs
    return zs


class ZoneSet:
    """The zones in force, packed for the kernels.  Immutable; empty is the common case.

    Args:
        zones: the zones; ids must be unique.

    Raises:
        ValueError: a repeated id.
    """

    __slots__ = (
        "__weakref__",
        "_bins",
        "_pickled",
        "boxes",
        "circles",
        "edges",
        "ids",
        "offsets",
        "search_margin_m",
        "zones",
    )

    def __init__(self, zones: Iterable[Zone] = ()) -> None:
        self._pickled: bytes | None = None  # ``__reduce__``'s, made at the first pickling
        self._bins: tuple[zone_bins.Bins | None] | None = None  # ``signed_distance``'s, made at its first use
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

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        """Pickled once, then the same bytes each time: a zone set is immutable, and every deliberation chunk
        and preview sent to a worker carries the one in force.  A terrain's slope barriers (346 zones over
        the Jacksboro DEM at 10 m) took 4.1-4.5 ms to pickle, in a pool thread holding the GIL, on every
        chunk of 8 jobs (BENCHMARKS.md, "Zone sets pickled once")."""
        got = self._pickled
        if got is None:
            state = (
                self.zones,
                self.ids,
                self.edges,
                self.offsets,
                self.circles,
                self.boxes,
                self.search_margin_m,
            )
            got = self._pickled = pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
        return _unpickled, (got,)

    def __copy__(self) -> ZoneSet:
        return self  # immutable

    def __deepcopy__(self, memo: dict[int, object]) -> ZoneSet:
        return self  # immutable: a copied stepper or view shares it

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

    def signed_distance(self, points: np.ndarray, reach: float = math.inf) -> np.ndarray:
        """Per point of ``(N, 2)``, metres to the nearest zone (<= 0 inside; ``inf`` with no zones, or
        none whose box is within ``reach``)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.full(len(pts), math.inf)
        if self.zones and len(pts):
            if self._bins is None:  # ``zone_bins``: of a terrain's hundreds of slope barriers, a point's few
                self._bins = (
                    zone_bins.bins_of(self.boxes) if len(self.zones) >= zone_bins.BINNED_FROM else None,
                )
            zone_bins.signed(
                self.edges, self.offsets, self.circles, self.boxes, self._bins[0], pts, out, reach
            )
        return out

    def nearest_many(self, points: np.ndarray) -> tuple[np.ndarray, list[str]]:
        """Per point, the signed distance to the nearest zone and its id (``""`` with no zones)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.full(len(pts), math.inf)
        idx = np.full(len(pts), -1, dtype=np.int64)
        if self.zones and len(pts):
            zone_kernels.nearest_many(self.edges, self.offsets, self.circles, self.boxes, pts, out, idx)
        return out, [self.ids[i] if i >= 0 else "" for i in idx.tolist()]

    def contains(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Boolean mask: which points lie in some zone (boundary included), or within ``margin_m`` of one."""
        # only zones whose box is within the margin can hold a point: the rest are skipped, not measured
        # (a terrain's hundreds of slope barriers; tests/unit/test_zones.py checks it against the full search)
        limit = max(TOUCH_M, margin_m)
        return self.signed_distance(points, limit) <= limit

    def zone_at(self, x: float, y: float) -> str:
        """The id of the zone holding ``(x, y)`` (the deepest), or ``""``."""
        if not self.zones:
            return ""
        sd, z, _, _ = zone_kernels.point_zone(
            self.edges, self.offsets, self.circles, self.boxes, x, y, math.inf
        )
        return self.ids[z] if sd <= TOUCH_M else ""

    def nearest(self, x: float, y: float) -> tuple[float, str, tuple[float, float]]:
        """``(signed distance, zone id, unit gradient)`` of the nearest zone (``inf, "", (0, 0)`` with none)."""
        if not self.zones:
            return math.inf, "", (0.0, 0.0)
        sd, z, gx, gy = zone_kernels.point_zone(
            self.edges, self.offsets, self.circles, self.boxes, x, y, math.inf
        )
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
        i, z = zone_kernels.first_hit(self.edges, self.offsets, self.circles, self.boxes, pts, margin_m)
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
        t, _ = zone_kernels.segment_hit(
            self.edges, self.offsets, self.circles, self.boxes, a[0], a[1], b[0], b[1]
        )
        return seg, max(float(t), 0.0), zid  # within the margin only: where the segment starts

    def segment_hits(self, path: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Per segment of the polyline ``path``: does it touch a zone (exactly), or come within ``margin_m``?"""
        pts = np.ascontiguousarray(path, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(max(len(pts) - 1, 0), dtype=np.bool_)
        if self.zones and len(pts) > 1:
            zone_kernels.segment_hits(self.edges, self.offsets, self.circles, self.boxes, pts, out, margin_m)
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
            lower = self._box_gaps(pts)
            for z in np.argsort(lower, kind="stable").tolist():
                if lower[z] > least:  # this zone and every later one are farther than the least so far
                    break
                least = min(least, float(self.zones[z].geometry.distance(line)))
            if self.first_hit(pts)[0] >= 0:
                least = min(least, 0.0)
        return least

    def _box_gaps(self, pts: np.ndarray) -> np.ndarray:
        """Per zone, at most its distance from the polyline ``pts``: the least gap between its box and a segment's.

        A zone's geometry lies in its box (a circle's polygon is inscribed in
        the circle).  Shaved by a hair, so rounding never makes it exceed the
        true distance.
        """
        lo = np.minimum(pts[:-1], pts[1:])
        hi = np.maximum(pts[:-1], pts[1:])
        b = self.boxes
        gx = np.maximum(np.maximum(b[:, None, 0] - hi[None, :, 0], lo[None, :, 0] - b[:, None, 2]), 0.0)
        gy = np.maximum(np.maximum(b[:, None, 1] - hi[None, :, 1], lo[None, :, 1] - b[:, None, 3]), 0.0)
        gap: np.ndarray = np.hypot(gx, gy).min(axis=1)
        return gap * (1.0 - 1e-9) - 1e-9 * float(np.abs(b).max())

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
            zone_kernels.raster(
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


def clear_run(zs: ZoneSet, x: float, y: float, dx: float, dy: float, reach: float, clear_m: float) -> float:
    """How far from ``(x, y)`` along the unit vector ``(dx, dy)``, at most ``reach``, a unit may go and
    end ``clear_m`` short of every zone of ``zs`` (0 when its way touches one at once)."""
    if not zs.zones or reach <= 0.0:
        return reach
    t, z = segment_hit(*zs.packed(), x, y, x + dx * reach, y + dy * reach)
    return reach if z < 0 else max(t * reach - clear_m, 0.0)
