"""One unit's route on the field's lattice by A*, with its levels and cores computed lazily and kept.

A lone unit's route search (``routes.RouteCache`` when its goal is not
shared) needs one path, not a cost-to-go from every node: building the whole
grid (its level raster, its core raster, every edge) and running Dijkstra
over all of it cost about 20 ms a look-ahead.  ``lazy_route`` searches a
``grid.GridGraph`` graph (16-connected, the same edges and edge costs) from
the unit to the goal by A*, and computes only what the search touches:

* the grid is the field's *lattice* for the cell ladder's rung at or just
  under the asked cell (``cell_ladder``: ``2 ** (k / LADDER)`` m, at most 9 %
  finer), its nodes at whole multiples of the cell, inside the asked box;
* the levels at half a cell and the cores at a quarter cell are filled tile
  by tile (``_TILE`` lattice points a side) the first time a search reads the
  tile, by the rasters' own rules (``kernels.raster_level``, the cores'
  ``_raster``), and kept per field and rung (``_KEPT`` lattices, at most
  ``_MAX_POINTS`` levels each), so the searches under one field share them.
  A value depends only on its absolute lattice index, never on what was
  filled before, so a preview and the live unit find the same route;
* an edge's length and Simpson exposure are computed when its node is
  expanded, by ``grid._edges``' formula.

The heuristic is the straight-line distance to the goal: an edge costs
``length + lambda * exposure`` with exposure never negative, so it is a lower
bound (and consistent), and the path found is a cheapest path of the graph,
as Dijkstra's would be (where two paths cost exactly the same, either may
come).  A search stays within the ellipse of cost ``J*`` round the unit and
the goal.

``lazy_route`` answers ``None`` where it does not apply, and the caller
builds the whole grid instead: keep-out zones in the search (their raster is
not tiled), a unit or goal whose own node lies in a core (the nearest open
node is a whole-grid question), and no path at all (whether the unit or the
goal is walled in is a whole-grid question too).
"""

from __future__ import annotations

import math
import weakref
from collections import OrderedDict

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.cores import Cores
from pfp_service.core.polylines import segment_hits
from pfp_service.core.threat import LEVEL_FLOOR, ThreatField

__all__ = ["LADDER", "LazyRoute", "cell_ladder", "clear_lattices", "lazy_route"]

_TILE = 16  # lattice points a side of a tile computed at once
LADDER = 8  # a lone search's cell is 2 ** (k / LADDER) m, so the searches under one field share lattices
_KING = ((1, 0), (0, 1), (1, 1), (1, -1))
_KNIGHT = ((2, 1), (1, 2), (2, -1), (1, -2))
_OFFSETS = np.array(_KING + _KNIGHT, dtype=np.int64)
_HEURISTIC = 1.0 - 1e-12  # the straight line, shaved by rounding's worth so it never overestimates
_FOUND, _NO_PATH, _SOURCE_SHUT, _TARGET_SHUT = 1, 0, -1, -2


@numba.njit(cache=True, nogil=True)
def _spans(packed: np.ndarray, h: float, floor: float, q_cap: float) -> tuple[np.ndarray, np.ndarray]:
    """Per threat, the lattice box ``(i0, i1, k0, k1)`` its raster visits (unclamped) and whether it counts.

    Exactly the box ``kernels.raster_level`` (``q_cap = Q_CUTOFF``) and the
    cores' ``_raster`` (``q_cap = inf``) compute, before clamping to the lattice.
    """
    m = packed.shape[0]
    box = np.zeros((m, 4), dtype=np.int64)
    use = np.zeros(m, dtype=np.bool_)
    for j in range(m):
        s = packed[j, kernels.SCALE]
        if packed[j, kernels.ACTIVE] == 0.0 or s < floor:
            continue
        qmax = min(2.0 * math.log(s / floor), q_cap)
        p00, p01, p11 = packed[j, kernels.P00], packed[j, kernels.P01], packed[j, kernels.P11]
        det = p00 * p11 - p01 * p01
        ex = math.sqrt(qmax * p11 / det) + h
        ey = math.sqrt(qmax * p00 / det) + h
        cx, cy = packed[j, kernels.XI_X], packed[j, kernels.XI_Y]
        box[j, 0] = math.floor((cx - ex) / h)
        box[j, 1] = math.ceil((cx + ex) / h)
        box[j, 2] = math.floor((cy - ey) / h)
        box[j, 3] = math.ceil((cy + ey) / h)
        use[j] = True
    return box, use


@numba.njit(cache=True, nogil=True)
def _fill_level(
    packed: np.ndarray,
    box: np.ndarray,
    use: np.ndarray,
    h: float,
    floor: float,
    out: np.ndarray,
    base_i: int,
    base_k: int,
    ti: int,
    tk: int,
) -> None:
    """The levels of tile ``(ti, tk)`` of ``out``, as ``kernels.raster_level`` sums them (threat by threat).

    Summed apart and then stored, so two searches filling one tile at once
    (threads, the GIL released) store the same values rather than adding twice.
    """
    nx, ny = out.shape  # out[0, 0] is lattice point (base_i, base_k), at (base_i h, base_k h)
    a0, a1 = base_i + ti * _TILE, base_i + min(nx - 1, ti * _TILE + _TILE - 1)
    b0, b1 = base_k + tk * _TILE, base_k + min(ny - 1, tk * _TILE + _TILE - 1)
    tile = np.zeros((a1 - a0 + 1, b1 - b0 + 1))
    for j in range(packed.shape[0]):
        if not use[j]:
            continue
        i0, i1 = max(a0, box[j, 0]), min(a1, box[j, 1])
        k0, k1 = max(b0, box[j, 2]), min(b1, box[j, 3])
        for i in range(i0, i1 + 1):
            x = i * h
            for k in range(k0, k1 + 1):
                tile[i - a0, k - b0] += kernels.threat_term(packed, j, x, k * h, floor, False)[0]
    out[a0 - base_i : a1 - base_i + 1, b0 - base_k : b1 - base_k + 1] = tile


@numba.njit(cache=True, nogil=True)
def _fill_cores(
    packed: np.ndarray,
    box: np.ndarray,
    use: np.ndarray,
    h: float,
    fraction: float,
    out: np.ndarray,
    base_i: int,
    base_k: int,
    ti: int,
    tk: int,
) -> None:
    """The core flags of tile ``(ti, tk)`` of ``out``, as the cores' ``_raster`` sets them."""
    nx, ny = out.shape  # out[0, 0] is lattice point (base_i, base_k), at (base_i h, base_k h)
    a0, a1 = base_i + ti * _TILE, base_i + min(nx - 1, ti * _TILE + _TILE - 1)
    b0, b1 = base_k + tk * _TILE, base_k + min(ny - 1, tk * _TILE + _TILE - 1)
    for j in range(packed.shape[0]):
        if not use[j]:
            continue
        i0, i1 = max(a0, box[j, 0]), min(a1, box[j, 1])
        k0, k1 = max(b0, box[j, 2]), min(b1, box[j, 3])
        for i in range(i0, i1 + 1):
            x = i * h
            for k in range(k0, k1 + 1):
                if out[i - base_i, k - base_k]:
                    continue
                if kernels.threat_term(packed, j, x, k * h, fraction, False)[0] >= fraction:
                    out[i - base_i, k - base_k] = True


@numba.njit(cache=True, nogil=True)
def _astar(  # type: ignore[no-untyped-def]
    packed, lfloor, lbox, luse, fine, fdone, fbi, fbk,
    cpacked, fraction, cbox, cuse, blocked, bdone, bbi, bbk,
    h, gi0, gk0, nx, ny, offsets, src, dst, lam, dropped,
):  # fmt: skip
    """``(status, node chain source first, cost, nodes expanded)``; status ``_FOUND`` or why not.

    Node ``(i, j)`` is lattice node ``(gi0 + i, gk0 + j)`` at ``((gi0 + i) h,
    (gk0 + j) h)``.  ``fine`` holds the levels at ``h / 2`` (its ``[0, 0]`` is
    half-cell point ``(fbi, fbk)``), ``blocked`` the cores at ``h / 4`` (from
    ``(bbi, bbk)``); tiles not yet ``done`` are filled when first needed.
    """
    empty = np.zeros(0, dtype=np.int64)
    fx, fy = fine.shape
    bx, by = blocked.shape
    hh, hq = 0.5 * h, 0.25 * h
    for s, code in ((src, _SOURCE_SHUT), (dst, _TARGET_SHUT)):
        bi, bk = 4 * (gi0 + s // ny) - bbi, 4 * (gk0 + s % ny) - bbk
        if not bdone[bi // _TILE, bk // _TILE]:
            _fill_cores(cpacked, cbox, cuse, hq, fraction, blocked, bbi, bbk, bi // _TILE, bk // _TILE)
            bdone[bi // _TILE, bk // _TILE] = True
        if blocked[bi, bk]:
            return code, empty, math.inf, 0
    n = nx * ny
    g = np.full(n, math.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    gxx, gyy = (gi0 + dst // ny) * h, (gk0 + dst % ny) * h
    cap = 1024
    hkey = np.empty(cap)
    hval = np.empty(cap, dtype=np.int64)
    size = 0
    g[src] = 0.0
    hkey[0] = _HEURISTIC * math.hypot(gxx - (gi0 + src // ny) * h, gyy - (gk0 + src % ny) * h)
    hval[0] = src
    size = 1
    m = offsets.shape[0]
    steps = np.empty((2 * m, 2), dtype=np.int64)
    for o in range(2 * m):
        sign = 1 if o < m else -1
        steps[o, 0], steps[o, 1] = sign * offsets[o % m, 0], sign * offsets[o % m, 1]
    expanded = 0
    while size > 0:
        u = hval[0]
        size -= 1
        if size > 0:  # sift the last entry down from the root
            key, val = hkey[size], hval[size]
            p = 0
            while True:
                c = 2 * p + 1
                if c >= size:
                    break
                if c + 1 < size and hkey[c + 1] < hkey[c]:
                    c += 1
                if hkey[c] >= key:
                    break
                hkey[p], hval[p] = hkey[c], hval[c]
                p = c
            hkey[p], hval[p] = key, val
        if closed[u]:
            continue
        closed[u] = True
        expanded += 1
        if u == dst:
            break
        i, j = u // ny, u % ny
        gu = g[u]
        fi, fj = 2 * (gi0 + i) - fbi, 2 * (gk0 + j) - fbk  # this node on the lattices
        qi, qj = 4 * (gi0 + i) - bbi, 4 * (gk0 + j) - bbk
        # the tiles this node's edges read, filled once here (its edges reach two cells)
        for ti in range(max(0, fi - 4) // _TILE, min(fx - 1, fi + 4) // _TILE + 1):
            for tk in range(max(0, fj - 4) // _TILE, min(fy - 1, fj + 4) // _TILE + 1):
                if not fdone[ti, tk]:
                    _fill_level(packed, lbox, luse, hh, lfloor, fine, fbi, fbk, ti, tk)
                    fdone[ti, tk] = True
        for ti in range(max(0, qi - 8) // _TILE, min(bx - 1, qi + 8) // _TILE + 1):
            for tk in range(max(0, qj - 8) // _TILE, min(by - 1, qj + 8) // _TILE + 1):
                if not bdone[ti, tk]:
                    _fill_cores(cpacked, cbox, cuse, hq, fraction, blocked, bbi, bbk, ti, tk)
                    bdone[ti, tk] = True
        lv0 = fine[fi, fj]
        for o in range(2 * m):
            di, dj = steps[o, 0], steps[o, 1]
            ti, tj = i + di, j + dj
            if ti < 0 or ti >= nx or tj < 0 or tj >= ny:
                continue
            v = ti * ny + tj
            if closed[v]:
                continue
            if (
                blocked[qi + 4 * di, qj + 4 * dj]
                or blocked[qi + di, qj + dj]
                or blocked[qi + 2 * di, qj + 2 * dj]
                or blocked[qi + 3 * di, qj + 3 * dj]
            ):
                continue
            if dropped.shape[0]:
                gone = False
                for d in range(dropped.shape[0]):
                    if (dropped[d, 0] == u and dropped[d, 1] == v) or (
                        dropped[d, 0] == v and dropped[d, 1] == u
                    ):
                        gone = True
                        break
                if gone:
                    continue
            lv1 = fine[fi + di, fj + dj]
            lv2 = fine[fi + 2 * di, fj + 2 * dj]
            ln = h * math.sqrt(di * di + dj * dj)
            cost = gu + (ln + lam * (ln * (lv0 + 4.0 * lv1 + lv2) / 6.0))
            if cost >= g[v]:
                continue
            g[v] = cost
            parent[v] = u
            if size == cap:
                cap *= 2
                nk = np.empty(cap)
                nv = np.empty(cap, dtype=np.int64)
                nk[:size] = hkey[:size]
                nv[:size] = hval[:size]
                hkey, hval = nk, nv
            key = cost + _HEURISTIC * math.hypot(gxx - (gi0 + ti) * h, gyy - (gk0 + tj) * h)
            p = size  # sift up
            size += 1
            while p > 0:
                up = (p - 1) // 2
                if hkey[up] <= key:
                    break
                hkey[p], hval[p] = hkey[up], hval[up]
                p = up
            hkey[p], hval[p] = key, v
    if not math.isfinite(g[dst]):
        return _NO_PATH, empty, math.inf, expanded
    k = 1
    w = dst
    while w != src:
        w = parent[w]
        k += 1
    chain = np.empty(k, dtype=np.int64)
    w = dst
    for t in range(k - 1, -1, -1):
        chain[t] = w
        w = parent[w]
    return _FOUND, chain, g[dst], expanded


class _Lattice:
    """One field's levels at ``h / 2`` and cores at ``h / 4`` for one cell ``h``, filled on demand and kept.

    Element ``[0, 0]`` of each array is an absolute lattice point whose
    indices are multiples of ``_TILE``, so tiles stay aligned as it grows.
    """

    __slots__ = ("bbase", "bdone", "blocked", "cbox", "cuse", "fbase", "fdone", "fine", "lbox", "luse")

    def __init__(self, packed: np.ndarray, lfloor: float, cores: Cores, h: float) -> None:
        self.lbox, self.luse = _spans(packed, 0.5 * h, lfloor, kernels.Q_CUTOFF)
        self.cbox, self.cuse = _spans(cores.packed, 0.25 * h, float(cores.fraction), math.inf)
        self.fine: np.ndarray = np.zeros((0, 0))
        self.fdone: np.ndarray = np.zeros((0, 0), dtype=np.bool_)
        self.blocked: np.ndarray = np.zeros((0, 0), dtype=np.bool_)
        self.bdone: np.ndarray = np.zeros((0, 0), dtype=np.bool_)
        self.fbase = self.bbase = (0, 0)

    def cover(self, gi0: int, gk0: int, nx: int, ny: int) -> bool:
        """Grow to hold nodes ``gi0 .. gi0 + nx - 1`` by ``gk0 .. gk0 + ny - 1``; ``False`` past ``_MAX_POINTS``."""
        for fine, scale in ((True, 2), (False, 4)):
            lat, done, base = (
                (self.fine, self.fdone, self.fbase) if fine else (self.blocked, self.bdone, self.bbase)
            )
            lo = (scale * gi0 // _TILE * _TILE, scale * gk0 // _TILE * _TILE)
            hi = (scale * (gi0 + nx - 1), scale * (gk0 + ny - 1))
            if lat.size:
                top = (base[0] + lat.shape[0] - 1, base[1] + lat.shape[1] - 1)
                if base[0] <= lo[0] and base[1] <= lo[1] and top[0] >= hi[0] and top[1] >= hi[1]:
                    continue
                lo = (min(lo[0], base[0]), min(lo[1], base[1]))
                hi = (max(hi[0], top[0]), max(hi[1], top[1]))
            shape = (-(-(hi[0] - lo[0] + 1) // _TILE) * _TILE, -(-(hi[1] - lo[1] + 1) // _TILE) * _TILE)
            if shape[0] * shape[1] > (1 if fine else 4) * _MAX_POINTS:
                return False
            grown = np.zeros(shape, dtype=lat.dtype)
            grown_done = np.zeros((shape[0] // _TILE, shape[1] // _TILE), dtype=np.bool_)
            if lat.size:
                oi, ok = base[0] - lo[0], base[1] - lo[1]
                grown[oi : oi + lat.shape[0], ok : ok + lat.shape[1]] = lat
                grown_done[
                    oi // _TILE : oi // _TILE + done.shape[0], ok // _TILE : ok // _TILE + done.shape[1]
                ] = done
            if fine:
                self.fine, self.fdone, self.fbase = grown, grown_done, lo
            else:
                self.blocked, self.bdone, self.bbase = grown, grown_done, lo
        return True

    @property
    def nbytes(self) -> int:
        """Memory held by the lattices."""
        return int(self.fine.nbytes + self.blocked.nbytes + self.fdone.nbytes + self.bdone.nbytes)


_MAX_POINTS = 1 << 18  # a kept lattice: at most this many levels (2 MB) and 4x as many core flags (1 MB)
_KEPT = 6  # lattices kept per process, the least recently used dropped first (a storm meets 4-5 rungs)
_LATTICES: OrderedDict[tuple[weakref.ref[ThreatField], float, int], _Lattice] = OrderedDict()


def _lattice(
    field: ThreatField, cores: Cores, packed: np.ndarray, lfloor: float, k: int, h: float
) -> _Lattice:
    """The kept lattice of ``field`` for rung ``k`` (cores are a function of the field and their fraction)."""
    for gone in [key for key in _LATTICES if key[0]() is None]:
        del _LATTICES[gone]
    key = (weakref.ref(field), float(cores.fraction), k)
    lat = _LATTICES.get(key)
    if lat is None:
        lat = _LATTICES[key] = _Lattice(packed, lfloor, cores, h)
        while len(_LATTICES) > _KEPT:
            _LATTICES.popitem(last=False)
    _LATTICES.move_to_end(key)
    return lat


def clear_lattices() -> None:
    """Forget every kept lattice (a cold start, as a new worker has)."""
    _LATTICES.clear()


def cell_ladder(cell_m: float) -> tuple[int, float]:
    """The rung ``k`` and cell ``2 ** (k / LADDER)`` at or just under ``cell_m`` (at most 9 % finer)."""
    k = math.floor(LADDER * math.log2(cell_m))
    while 2.0 ** ((k + 1) / LADDER) <= cell_m:
        k += 1
    while 2.0 ** (k / LADDER) > cell_m:
        k -= 1
    return k, 2.0 ** (k / LADDER)


class LazyRoute:
    """A path found by ``lazy_route``: its nodes, their coordinates, its cost and the searches' work."""

    __slots__ = ("corners", "cost", "expanded", "nodes", "points", "searches")

    def __init__(
        self,
        nodes: np.ndarray,
        points: np.ndarray,
        cost: float,
        expanded: int,
        searches: int,
        corners: np.ndarray,
    ) -> None:
        self.corners = corners  # indices of the nodes where the path turns, first and last included
        self.nodes = nodes
        self.points = points
        self.cost = cost
        self.expanded = expanded
        self.searches = searches


def lazy_route(
    field: ThreatField,
    box: tuple[tuple[float, float], tuple[float, float]],
    cores: Cores,
    cell_m: float,
    source: tuple[float, float],
    goal: tuple[float, float],
    lam: float,
    repairs: int,
) -> LazyRoute | None:
    """The cheapest path between the nodes nearest ``source`` and ``goal`` on the field's lattice of the rung
    at or under ``cell_m``, inside ``box``, its edges checked against the cores as ``GridGraph.route`` checks
    them; or ``None`` where the whole grid must be built instead (see the module's docstring)."""
    if cores.zones or not cell_m > 0:
        return None
    k, h = cell_ladder(cell_m)
    (x0, y0), (x1, y1) = box
    gi0, gk0 = math.ceil(x0 / h), math.ceil(y0 / h)  # inward: never past the asked box (or the bounds)
    nx = max(2, math.floor(x1 / h) - gi0 + 1)
    ny = max(2, math.floor(y1 / h) - gk0 + 1)

    def node(x: float, y: float) -> int:
        i = min(max(round(x / h) - gi0, 0), nx - 1)
        j = min(max(round(y / h) - gk0, 0), ny - 1)
        return int(i * ny + j)

    src, dst = node(*source), node(*goal)
    packed = np.ascontiguousarray(field.packed)
    peak = float(np.max(packed[:, kernels.SCALE])) if len(field) else 0.0
    if peak <= 0:
        packed = np.zeros((0, len(kernels.PACKED_COLUMNS)))
    lfloor = LEVEL_FLOOR * peak
    lat = _lattice(field, cores, packed, lfloor, k, h)
    if not lat.cover(gi0, gk0, nx, ny):  # too big to keep: this search's own
        lat = _Lattice(packed, lfloor, cores, h)
        if not lat.cover(gi0, gk0, nx, ny):  # past any lattice's cap: the kernel would write outside it
            return None
    cpacked = np.ascontiguousarray(cores.packed)
    dropped: list[tuple[int, int]] = []
    expanded = 0
    for attempt in range(repairs + 1):
        status, chain, cost, work = _astar(
            packed, lfloor, lat.lbox, lat.luse, lat.fine, lat.fdone, lat.fbase[0], lat.fbase[1],
            cpacked, float(cores.fraction), lat.cbox, lat.cuse, lat.blocked, lat.bdone, lat.bbase[0], lat.bbase[1],
            h, gi0, gk0, nx, ny, _OFFSETS, src, dst, float(lam),
            np.array(dropped, dtype=np.int64).reshape(-1, 2),
        )  # fmt: skip
        expanded += work
        if status != _FOUND:
            return None
        pts = np.stack([(gi0 + chain // ny) * h, (gk0 + chain % ny) * h], axis=1)
        if attempt == repairs:
            break
        bad = np.flatnonzero(segment_hits(cores, pts)) if len(pts) >= 2 else np.zeros(0, dtype=np.int64)
        if not len(bad):
            break
        dropped.extend((int(chain[b]), int(chain[b + 1])) for b in bad)
    ij = np.stack([chain // ny, chain % ny], axis=1)
    step = np.diff(ij, axis=0)
    turn = np.flatnonzero(np.any(step[1:] != step[:-1], axis=1)) + 1  # where the heading changes
    corners = np.concatenate([[0], turn, [len(chain) - 1]]) if len(chain) > 1 else np.zeros(1)
    return LazyRoute(chain, pts, float(cost), expanded, attempt + 1, corners.astype(np.int64))
