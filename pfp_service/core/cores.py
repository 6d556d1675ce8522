"""Threat cores: the regions no escape may drive through, and the test for them.

Definition (also in docs/algorithm.md, "Threat cores"):  a point ``x`` lies in
the *core* of threat ``j`` when that threat's own level is at least half its
peak, ``t_j(x) >= CORE_FRACTION * max t_j`` with ``CORE_FRACTION = 0.5``: the
threat's half-maximum region.  For an unskewed threat that is the ellipse of
Mahalanobis radius ``sqrt(2 ln 2) ~= 1.18``, i.e. 1.18 ``sigma_range`` along
the facing and 1.18 ``sigma_lateral`` across it; skew pushes it forward.  The
test is per threat, so it does not depend on the weight or the intensity
scale, and overlapping tails of several threats never make a core.  A threat
of weight 0 has no core.

Paths are tested densely: segments are subdivided to a quarter of the
narrowest threat spread, so no core is stepped over between two points.

One rule, one margin.  Every check (an escape's judge, the benchmark's core
entries) uses ``CORE_FRACTION``.  The route searches (the ``global`` escape,
``--planner optimal --avoid-cores``) leave out the slightly larger region
``SEARCH_FRACTION = 0.48`` of peak: a route between grid points then keeps a
sliver of clearance (0.034 standard deviations across an unskewed core) and
always passes the check.  The price is explicit: a gap whose middle is
between 0.48 and 0.5 of peak is open by the rule but not searched through;
``pfp bench quality`` counts such cases as ambiguous.

Keep-out zones are regions of the same kind.  ``Cores`` holds the field's
zones (``ThreatField.zones``) beside its threat cores, so every test here --
``inside``, ``first_hit``, ``segment_hits``, ``raster``, ``core_at`` -- covers
both, and everything built on cores (escapes, the ``global`` route, the
route grids, ``--avoid-cores``, the benchmark's checks) keeps out of zones with
no other change.  Zones are tested exactly (``core.zones``: a segment's
contact is solved, not sampled); their raster blocks every lattice node within
1.12 lattice spacings of a zone, so no lattice edge of the route grids (a king
or knight move, sampled at its ends, quarter points and midpoint) steps over
one however thin; a route that still clips one is repaired as for a core
(``GridGraph.drop_clipping``).  A hit is named by ``region``: ``zone Z`` for a
zone, ``the core of threat T`` for a core.
"""

from __future__ import annotations

import math
import weakref

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.threat import ThreatField
from pfp_service.core.visibility import unmasked
from pfp_service.core.zones import ZoneSet

__all__ = ["CORE_FRACTION", "SEARCH_FRACTION", "ZONE_PREFIX", "ZONE_RASTER_SPACINGS", "Cores"]

CORE_FRACTION = 0.5
SEARCH_FRACTION = 0.48
# A zone blocks raster nodes this many lattice spacings from it: half a knight move's sample gap (sqrt(5)/2).
ZONE_RASTER_SPACINGS = 1.12
ZONE_PREFIX = "zone "  # a hit on a zone is named "zone Z" (a threat id has no space)


@numba.njit(cache=True, nogil=True)
def _ratios(packed: np.ndarray, points: np.ndarray, out_ratio: np.ndarray, out_idx: np.ndarray) -> None:
    """Per point, the largest ``t_j / max t_j`` over threats and which threat gives it."""
    for i in range(points.shape[0]):
        best = 0.0
        arg = -1
        for j in range(packed.shape[0]):
            r = kernels.threat_term(packed, j, points[i, 0], points[i, 1], 0.0, False)[0]
            if r > best:
                best = r
                arg = j
        out_ratio[i] = best
        out_idx[i] = arg


@numba.njit(cache=True, nogil=True)
def _inside(packed: np.ndarray, points: np.ndarray, fraction: float, out: np.ndarray) -> None:
    """``out[i]``: some ``t_j / max t_j >= fraction`` at point i (exactly ``_ratios``' test, sooner)."""
    for i in range(points.shape[0]):
        hit = False
        for j in range(packed.shape[0]):
            if kernels.threat_term(packed, j, points[i, 0], points[i, 1], fraction, False)[0] >= fraction:
                hit = True
                break
        out[i] = hit


@numba.njit(cache=True, nogil=True)
def _raster(packed: np.ndarray, x0: float, y0: float, h: float, fraction: float, out: np.ndarray) -> None:
    """``out[i, k]`` |= node ``(x0 + i h, y0 + k h)`` lies in some core; each threat visits only its box.

    A threat's core needs ``scale exp(-q/2) >= fraction`` (its skew factor is at
    most 1), i.e. ``q <= 2 ln(scale / fraction)``: an ellipse whose bounding box
    has half-widths ``sqrt(q_max Omega_00)`` and ``sqrt(q_max Omega_11)``.
    """
    nx, ny = out.shape
    for j in range(packed.shape[0]):
        s = packed[j, kernels.SCALE]
        if packed[j, kernels.ACTIVE] == 0.0 or s < fraction:
            continue
        qmax = 2.0 * math.log(s / fraction)
        p00, p01, p11 = packed[j, kernels.P00], packed[j, kernels.P01], packed[j, kernels.P11]
        det = p00 * p11 - p01 * p01
        ex = math.sqrt(qmax * p11 / det) + h
        ey = math.sqrt(qmax * p00 / det) + h
        cx, cy = packed[j, kernels.XI_X], packed[j, kernels.XI_Y]
        i0 = max(0, math.floor((cx - ex - x0) / h))
        i1 = min(nx - 1, math.ceil((cx + ex - x0) / h))
        k0 = max(0, math.floor((cy - ey - y0) / h))
        k1 = min(ny - 1, math.ceil((cy + ey - y0) / h))
        for i in range(i0, i1 + 1):
            x = x0 + i * h
            for k in range(k0, k1 + 1):
                if out[i, k]:
                    continue
                if kernels.threat_term(packed, j, x, y0 + k * h, fraction, False)[0] >= fraction:
                    out[i, k] = True


class Cores:
    """The cores of one threat field.

    Args:
        field: the threats in force.
        fraction: the share of each threat's peak that bounds its core.
    """

    __slots__ = ("boxes", "fraction", "ids", "min_spread_m", "packed", "zone_margin_m", "zones")

    def __init__(self, field: ThreatField, fraction: float = CORE_FRACTION) -> None:
        self.fraction = fraction
        keep = [j for j, t in enumerate(field.threats) if t.weight > 0]
        # a core is nearness to the enemy, not its sight: over terrain it stays unmasked (the safe side)
        packed = unmasked(field.packed[keep]) if keep else np.zeros((0, len(kernels.PACKED_COLUMNS)))
        for row, j in enumerate(keep):
            t = field.threats[j]
            packed[row, kernels.SCALE] = t.density_scale() / t.peak_density()  # level 1 at the mode
        self.packed = packed
        self.ids = [field.threats[j].id or f"#{j + 1}" for j in keep]
        self.min_spread_m = min((field.threats[j].min_sigma() for j in keep), default=math.inf)
        # per threat, the box outside which its core cannot reach (as in ``_raster``)
        scale = packed[:, kernels.SCALE]
        qmax = 2.0 * np.log(np.maximum(scale, fraction) / fraction)
        det = packed[:, kernels.P00] * packed[:, kernels.P11] - packed[:, kernels.P01] ** 2
        ex = np.sqrt(qmax * packed[:, kernels.P11] / det) if len(packed) else np.zeros(0)
        ey = np.sqrt(qmax * packed[:, kernels.P00] / det) if len(packed) else np.zeros(0)
        cx, cy = packed[:, kernels.XI_X], packed[:, kernels.XI_Y]
        self.boxes = np.stack([cx - ex, cy - ey, cx + ex, cy + ey], axis=1)
        self.zones: ZoneSet = field.zones
        # a search's cores (below CORE_FRACTION) keep a hair's clearance from zones too
        self.zone_margin_m = field.zones.search_margin_m if fraction < CORE_FRACTION else 0.0

    @staticmethod
    def region(hit: str) -> str:
        """What a hit of ``core_at`` or ``first_hit`` names: ``zone Z`` or ``the core of threat T``."""
        return hit if hit.startswith(ZONE_PREFIX) else f"the core of threat {hit}"

    @classmethod
    def of(cls, field: ThreatField, fraction: float = CORE_FRACTION) -> Cores:
        """The cores of ``field``, built once per field and fraction (a field is immutable)."""
        per_field = _CACHE.setdefault(field, {})
        if fraction not in per_field:
            per_field[fraction] = cls(field, fraction)
        return per_field[fraction]

    def ratio(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Largest normalised threat level ``t_j / max t_j`` at each point, and its threat index."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        ratio = np.zeros(len(pts))
        idx = np.full(len(pts), -1, dtype=np.int64)
        if len(self.packed) and len(pts):
            _ratios(self.packed, pts, ratio, idx)
        return ratio, idx

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask: which points lie in some threat's core or in a zone.

        Exact at any size; many points among many threats are cut into tiles,
        each tested against only the threats whose core box meets it.
        """
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = self.inside_cores(pts)
        if self.zones and len(pts):
            out |= self.zones.contains(pts, self.zone_margin_m)
        return out

    def first_clear(self, rays: np.ndarray, chunk: int = 64) -> np.ndarray:
        """Per ray of ``(m, n, 2)`` points, the index of its first point ``inside`` holds not (``n``: none).

        What ``argmin`` over ``inside`` of every point gives, but only the rays still undecided are
        measured, ``chunk`` points of each at a time, and the zones (a terrain's hundreds of slope
        barriers, tested edge by edge) only at points in no core: a ray is decided at its first clear
        point, and nothing beyond it is asked.  (Every point of 72 rays of 2,000 measured took 0.5 s a
        unit inside a wide threat's core over the Jacksboro DEM's barriers; BENCHMARKS.md.)
        """
        m, n = rays.shape[0], rays.shape[1]
        out = np.full(m, n, dtype=np.int64)
        undecided = np.arange(m)
        a = 0
        while a < n and len(undecided):
            b = min(a + chunk, n)
            asked = np.ascontiguousarray(rays[undecided, a:b], dtype=np.float64).reshape(-1, 2)
            clear = ~self.inside_cores(asked)
            if self.zones:
                free = np.flatnonzero(clear)
                clear[free] = ~self.zones.contains(asked[free], self.zone_margin_m)
            clear = clear.reshape(len(undecided), b - a)
            done = clear.any(axis=1)
            out[undecided[done]] = a + np.argmax(clear[done], axis=1)
            undecided = undecided[~done]
            a = b
        return out

    def inside_cores(self, points: np.ndarray) -> np.ndarray:
        """``inside`` for the threat cores alone (zones are tested exactly, segment by segment)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(pts), dtype=np.bool_)
        if not (len(self.packed) and len(pts)):
            return out
        tiles = min(16, int(math.sqrt(len(pts) * len(self.packed) / 20_000.0)))
        if tiles < 2:
            _inside(self.packed, pts, self.fraction, out)
            return out
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        size = np.maximum((hi - lo) / tiles, 1e-300)
        cell = np.minimum(((pts - lo) / size).astype(np.int64), tiles - 1)
        key = cell[:, 0] * tiles + cell[:, 1]
        order = np.argsort(key, kind="stable")
        cuts = np.searchsorted(key[order], np.arange(tiles * tiles + 1))
        b = self.boxes
        for t in range(tiles * tiles):
            rows = order[cuts[t] : cuts[t + 1]]
            if not len(rows):
                continue
            sub = pts[rows]
            tlo, thi = sub.min(axis=0), sub.max(axis=0)
            near = (b[:, 0] <= thi[0]) & (b[:, 2] >= tlo[0]) & (b[:, 1] <= thi[1]) & (b[:, 3] >= tlo[1])
            if near.any():
                hit = np.zeros(len(rows), dtype=np.bool_)
                _inside(
                    np.ascontiguousarray(self.packed[near]), np.ascontiguousarray(sub), self.fraction, hit
                )
                out[rows] = hit
        return out

    def raster(self, origin: tuple[float, float], cell_m: float, shape: tuple[int, int]) -> np.ndarray:
        """Boolean ``shape`` grid: node ``(origin + (i, k) cell_m)`` lies in a core (exactly ``inside``)."""
        out = np.zeros(shape, dtype=np.bool_)
        if len(self.packed):
            _raster(self.packed, float(origin[0]), float(origin[1]), float(cell_m), self.fraction, out)
        if self.zones:
            out |= self.zones.raster(
                origin, cell_m, shape, ZONE_RASTER_SPACINGS * cell_m + self.zone_margin_m
            )
        return out

    def core_at(self, x: float, y: float) -> str:
        """The id of the threat whose core holds ``(x, y)`` (the deepest one), ``zone Z``, or ``""``."""
        zone = self.zones.zone_at(x, y) if self.zones else ""
        if zone:
            return ZONE_PREFIX + zone
        if not len(self.packed):
            return ""
        ratio, idx = self.ratio(np.array([[x, y]]))
        return self.ids[int(idx[0])] if ratio[0] >= self.fraction else ""

    def first_hit(self, path: np.ndarray) -> str:
        """The id of the first core the polyline ``path`` enters, ``zone Z`` for a zone, or ``""`` if none."""
        raw = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        seg, t, zone = self.zones.first_contact(raw, self.zone_margin_m) if self.zones else (-1, 0.0, "")
        if seg >= 0:  # only the part up to the zone's segment can meet a core first
            raw = raw[: seg + 2]
        pts = self.densify(raw)
        if len(self.packed) and len(pts):
            hits = np.flatnonzero(self.inside_cores(pts))
            if len(hits):
                _, idx = self.ratio(pts[hits[0] : hits[0] + 1])  # the deepest core at the first point inside
                if seg < 0:
                    return self.ids[int(idx[0])]
                arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
                legs = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(raw, axis=0).T))])
                if arc[hits[0]] <= legs[seg] + t * (legs[seg + 1] - legs[seg]):
                    return self.ids[int(idx[0])]
        return ZONE_PREFIX + zone if zone else ""

    def segment_hits(self, path: np.ndarray) -> np.ndarray:
        """Per segment of the polyline ``path``: does it enter a core (sampled as ``first_hit`` samples it)?"""
        pts = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        zoned = (
            self.zones.segment_hits(pts, self.zone_margin_m)
            if self.zones
            else np.zeros(max(len(pts) - 1, 0), dtype=bool)
        )
        if len(pts) < 2 or not len(self.packed):
            return zoned
        seg = np.diff(pts, axis=0)
        if math.isfinite(self.min_spread_m):
            n = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / (self.min_spread_m / 4.0))).astype(
                np.int64
            )
        else:
            n = np.ones(len(seg), dtype=np.int64)
        which = np.repeat(np.arange(len(seg)), n + 1)  # every sample of a segment, both ends included
        k = np.arange(len(which)) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)
        t = (k / n[which])[:, None]
        inside = self.inside_cores(pts[:-1][which] + t * seg[which])
        hits: np.ndarray = np.logical_or.reduceat(inside, np.cumsum(n + 1) - (n + 1))
        out: np.ndarray = hits | zoned
        return out

    def densify(self, path: np.ndarray) -> np.ndarray:
        """``path`` with every segment split to at most a quarter of the narrowest standard deviation."""
        if len(path) < 2 or not math.isfinite(self.min_spread_m):
            return path
        h = self.min_spread_m / 4.0
        seg = np.diff(path, axis=0)
        n = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / h)).astype(np.int64)
        if int(n.max()) == 1:
            return path
        which = np.repeat(np.arange(len(seg)), n)
        k = np.arange(len(which)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each segment
        t = (k / n[which])[:, None]
        return np.concatenate([path[:1], path[:-1][which] + t * seg[which]])


_CACHE: weakref.WeakKeyDictionary[ThreatField, dict[float, Cores]] = weakref.WeakKeyDictionary()
