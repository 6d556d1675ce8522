"""One unit's route on ``grid.GridGraph``'s lattice by A*, with the lattice's levels and cores computed lazily.

A lone unit's route search (``routes.RouteCache`` when its goal is not
shared) needs one path, not a cost-to-go from every node: building the whole
grid (its level raster, its core raster, every edge) and running Dijkstra
over all of it cost about 20 ms a look-ahead.  ``lazy_route`` searches the
*same graph*, node for node and edge for edge, but from the unit to the
goal by A* and computes only what the search touches:

* the levels at half a cell and the cores at a quarter cell are filled tile by
  tile (``_TILE`` lattice points a side) the first time the search reads a
  point of the tile, by the rasters' own rules (``kernels.raster_level``, the
  cores' ``_raster``), each threat over its own box clipped to the tile, the
  threats in the same order: every value equals the whole raster's;
* an edge's length and Simpson exposure are computed when its node is
  expanded, by ``grid._edges``' formula.

The heuristic is the straight-line distance to the goal: an edge costs
``length + lambda * exposure`` with exposure never negative, so it is a lower
bound (and consistent), and the path found is a cheapest path of the graph,
as Dijkstra's is (where two paths cost exactly the same, either may come).
A search stays within the ellipse of cost ``J*`` round the unit and the goal.

``lazy_route`` answers ``None`` where it does not apply, and the caller
builds the whole grid instead: keep-out zones in the search (their raster is
not tiled), a unit or goal whose own node lies in a core (the nearest open
node is a whole-grid question), and no path at all (whether the unit or the
goal is walled in is a whole-grid question too).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.cores import Cores
from pfp_service.core.grid import segment_hits
from pfp_service.core.threat import LEVEL_FLOOR, ThreatField

__all__ = ["LazyRoute", "lazy_route"]

_TILE = 16  # lattice points a side of a tile computed at once
_KING = ((1, 0), (0, 1), (1, 1), (1, -1))
_KNIGHT = ((2, 1), (1, 2), (2, -1), (1, -2))
_OFFSETS = np.array(_KING + _KNIGHT, dtype=np.int64)
_HEURISTIC = 1.0 - 1e-12  # the straight line, shaved by rounding's worth so it never overestimates
_FOUND, _NO_PATH, _SOURCE_SHUT, _TARGET_SHUT = 1, 0, -1, -2


@numba.njit(cache=True, nogil=True)
def _spans(
    packed: np.ndarray, x0: float, y0: float, h: float, floor: float, q_cap: float
) -> tuple[np.ndarray, np.ndarray]:
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
        box[j, 0] = math.floor((cx - ex - x0) / h)
        box[j, 1] = math.ceil((cx + ex - x0) / h)
        box[j, 2] = math.floor((cy - ey - y0) / h)
        box[j, 3] = math.ceil((cy + ey - y0) / h)
        use[j] = True
    return box, use


@numba.njit(cache=True, nogil=True)
def _fill_level(
    packed: np.ndarray,
    box: np.ndarray,
    use: np.ndarray,
    x0: float,
    y0: float,
    h: float,
    floor: float,
    out: np.ndarray,
    ti: int,
    tk: int,
) -> None:
    """The levels of tile ``(ti, tk)`` of ``out``, as ``kernels.raster_level`` sums them (threat by threat)."""
    nx, ny = out.shape
    a0, a1 = ti * _TILE, min(nx - 1, ti * _TILE + _TILE - 1)
    b0, b1 = tk * _TILE, min(ny - 1, tk * _TILE + _TILE - 1)
    for j in range(packed.shape[0]):
        if not use[j]:
            continue
        i0, i1 = max(a0, box[j, 0]), min(a1, box[j, 1])
        k0, k1 = max(b0, box[j, 2]), min(b1, box[j, 3])
        for i in range(i0, i1 + 1):
            x = x0 + i * h
            for k in range(k0, k1 + 1):
                out[i, k] += kernels.threat_term(packed, j, x, y0 + k * h, floor, False)[0]


@numba.njit(cache=True, nogil=True)
def _fill_cores(
    packed: np.ndarray,
    box: np.ndarray,
    use: np.ndarray,
    x0: float,
    y0: float,
    h: float,
    fraction: float,
    out: np.ndarray,
    ti: int,
    tk: int,
) -> None:
    """The core flags of tile ``(ti, tk)`` of ``out``, as the cores' ``_raster`` sets them."""
    nx, ny = out.shape
    a0, a1 = ti * _TILE, min(nx - 1, ti * _TILE + _TILE - 1)
    b0, b1 = tk * _TILE, min(ny - 1, tk * _TILE + _TILE - 1)
    for j in range(packed.shape[0]):
        if not use[j]:
            continue
        i0, i1 = max(a0, box[j, 0]), min(a1, box[j, 1])
        k0, k1 = max(b0, box[j, 2]), min(b1, box[j, 3])
        for i in range(i0, i1 + 1):
            x = x0 + i * h
            for k in range(k0, k1 + 1):
                if out[i, k]:
                    continue
                if kernels.threat_term(packed, j, x, y0 + k * h, fraction, False)[0] >= fraction:
                    out[i, k] = True


@numba.njit(cache=True, nogil=True)
def _astar(
    packed: np.ndarray,
    lfloor: float,
    cpacked: np.ndarray,
    fraction: float,
    check: bool,
    x0: float,
    y0: float,
    h: float,
    nx: int,
    ny: int,
    offsets: np.ndarray,
    src: int,
    dst: int,
    lam: float,
    dropped: np.ndarray,
) -> tuple[int, np.ndarray, float, int]:
    """``(status, node chain source first, cost, nodes expanded)``; status ``_FOUND`` or why not."""
    empty = np.zeros(0, dtype=np.int64)
    fx, fy = 2 * nx - 1, 2 * ny - 1
    bx, by = 4 * nx - 3, 4 * ny - 3
    fine = np.zeros((fx, fy))
    fdone = np.zeros(((fx + _TILE - 1) // _TILE, (fy + _TILE - 1) // _TILE), dtype=np.bool_)
    blocked = np.zeros((bx, by), dtype=np.bool_)
    bdone = np.zeros(((bx + _TILE - 1) // _TILE, (by + _TILE - 1) // _TILE), dtype=np.bool_)
    hh, hq = 0.5 * h, 0.25 * h
    lbox, luse = _spans(packed, x0, y0, hh, lfloor, kernels.Q_CUTOFF)
    cbox, cuse = _spans(cpacked, x0, y0, hq, fraction, math.inf)
    if check:
        for s, code in ((src, _SOURCE_SHUT), (dst, _TARGET_SHUT)):
            bi, bk = 4 * (s // ny), 4 * (s % ny)
            if not bdone[bi // _TILE, bk // _TILE]:
                _fill_cores(cpacked, cbox, cuse, x0, y0, hq, fraction, blocked, bi // _TILE, bk // _TILE)
                bdone[bi // _TILE, bk // _TILE] = True
            if blocked[bi, bk]:
                return code, empty, math.inf, 0
    n = nx * ny
    g = np.full(n, math.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    gxx, gyy = x0 + h * (dst // ny), y0 + h * (dst % ny)
    cap = 1024
    hkey = np.empty(cap)
    hval = np.empty(cap, dtype=np.int64)
    size = 0
    g[src] = 0.0
    hkey[0] = _HEURISTIC * math.hypot(gxx - (x0 + h * (src // ny)), gyy - (y0 + h * (src % ny)))
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
        # the tiles this node's edges read, filled once here (its edges reach two cells)
        for ti in range(max(0, 2 * i - 4) // _TILE, min(fx - 1, 2 * i + 4) // _TILE + 1):
            for tk in range(max(0, 2 * j - 4) // _TILE, min(fy - 1, 2 * j + 4) // _TILE + 1):
                if not fdone[ti, tk]:
                    _fill_level(packed, lbox, luse, x0, y0, hh, lfloor, fine, ti, tk)
                    fdone[ti, tk] = True
        if check:
            for ti in range(max(0, 4 * i - 8) // _TILE, min(bx - 1, 4 * i + 8) // _TILE + 1):
                for tk in range(max(0, 4 * j - 8) // _TILE, min(by - 1, 4 * j + 8) // _TILE + 1):
                    if not bdone[ti, tk]:
                        _fill_cores(cpacked, cbox, cuse, x0, y0, hq, fraction, blocked, ti, tk)
                        bdone[ti, tk] = True
        lv0 = fine[2 * i, 2 * j]
        for o in range(2 * m):
            di, dj = steps[o, 0], steps[o, 1]
            ti, tj = i + di, j + dj
            if ti < 0 or ti >= nx or tj < 0 or tj >= ny:
                continue
            v = ti * ny + tj
            if closed[v]:
                continue
            if check and (
                blocked[4 * ti, 4 * tj]
                or blocked[4 * i + di, 4 * j + dj]
                or blocked[4 * i + 2 * di, 4 * j + 2 * dj]
                or blocked[4 * i + 3 * di, 4 * j + 3 * dj]
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
            lv1 = fine[2 * i + di, 2 * j + dj]
            lv2 = fine[2 * ti, 2 * tj]
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
            key = cost + _HEURISTIC * math.hypot(gxx - (x0 + h * ti), gyy - (y0 + h * tj))
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


class LazyRoute:
    """A path found by ``lazy_route``: its nodes, their coordinates, its cost and the searches' work."""

    __slots__ = ("cost", "expanded", "nodes", "points", "searches")

    def __init__(
        self, nodes: np.ndarray, points: np.ndarray, cost: float, expanded: int, searches: int
    ) -> None:
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
    """The cheapest path of ``GridGraph(field, box, cores=cores, cell_m=cell_m)`` (16-connected) between the nodes of
    ``source`` and ``goal``, with its edges checked against the cores as ``GridGraph.route`` checks them; or
    ``None`` where the whole grid must be built instead (see the module's docstring)."""
    if cores.zones or not cell_m > 0:
        return None
    (x0, y0), (x1, y1) = box
    h = cell_m
    nx = max(2, math.ceil((x1 - x0) / h) + 1)
    ny = max(2, math.ceil((y1 - y0) / h) + 1)

    def node(x: float, y: float) -> int:  # GridGraph.cell_of
        i = min(max(round((x - x0) / h), 0), nx - 1)
        j = min(max(round((y - y0) / h), 0), ny - 1)
        return int(i * ny + j)

    src, dst = node(*source), node(*goal)
    packed = np.ascontiguousarray(field.packed)
    peak = float(np.max(packed[:, kernels.SCALE])) if len(field) else 0.0
    if peak <= 0:
        packed = np.zeros((0, packed.shape[1] if packed.ndim == 2 else len(kernels.PACKED_COLUMNS)))
    cpacked = np.ascontiguousarray(cores.packed)
    dropped: list[tuple[int, int]] = []
    expanded = 0
    for attempt in range(repairs + 1):
        status, chain, cost, work = _astar(
            packed,
            LEVEL_FLOOR * peak,
            cpacked,
            float(cores.fraction),
            True,
            float(x0),
            float(y0),
            float(h),
            nx,
            ny,
            _OFFSETS,
            src,
            dst,
            float(lam),
            np.array(dropped, dtype=np.int64).reshape(-1, 2),
        )
        expanded += work
        if status != _FOUND:
            return None
        pts = np.stack([x0 + h * (chain // ny), y0 + h * (chain % ny)], axis=1)
        if attempt == repairs:
            break
        bad = np.flatnonzero(segment_hits(cores, pts)) if len(pts) >= 2 else np.zeros(0, dtype=np.int64)
        if not len(bad):
            break
        dropped.extend((int(chain[b]), int(chain[b + 1])) for b in bad)
    return LazyRoute(chain, pts, float(cost), expanded, attempt + 1)
