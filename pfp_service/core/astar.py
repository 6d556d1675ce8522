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
  by tile the first time a search reads the tile, and kept per field and
  rung (``core.lattice``), so the searches under one field share them;
* an edge's length and Simpson exposure are computed when its node is
  expanded, by ``grid._edges``' formula.

The heuristic is the straight-line distance to the goal: an edge costs
``length + lambda * exposure`` with exposure never negative, so it is a lower
bound (and consistent), and the path found is a cheapest path of the graph,
as Dijkstra's would be (where two paths cost exactly the same, either may
come).  A search stays within the ellipse of cost ``J*`` round the unit and
the goal.

With keep-out zones in force (slope barriers over terrain among them) the
search runs on the very grid ``GridGraph`` would build for the ask (its cell
and its origin at the box's corner, on a lattice of its own, not kept), so
it finds the grid's route without building the grid: the zones are rastered
at a quarter cell over the search's nodes by ``Cores.raster``'s rule (within
``ZONE_RASTER_SPACINGS`` quarter cells of a zone, plus the search's hair of
clearance), each edge is checked against them where it is checked against
the cores, a route that still clips a zone is repaired as one that clips a
core is (``segment_hits`` tests zones exactly), and every node goes to the
shortcut, as from the grid's walk.

``lazy_route`` answers ``None`` where it does not apply, and the caller
builds the whole grid instead: a unit or goal whose own node lies in a core
or a zone (the nearest open node is a whole-grid question), and no path at
all (whether the unit or the goal is walled in is a whole-grid question too).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.cores import ZONE_RASTER_SPACINGS, Cores
from pfp_service.core.lattice import (
    LADDER,
    TILE,
    Lattice,
    cell_ladder,
    clear_lattices,
    fill_cores,
    fill_level,
    kept_lattice,
)
from pfp_service.core.polylines import segment_hits
from pfp_service.core.threat import LEVEL_FLOOR, ThreatField

__all__ = ["LADDER", "LazyRoute", "cell_ladder", "clear_lattices", "lazy_route"]

_OFFSETS = np.array(((1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2)))  # king, knight
_HEURISTIC = 1.0 - 1e-12  # the straight line, shaved by rounding's worth so it never overestimates
_FOUND, _NO_PATH, _SOURCE_SHUT, _TARGET_SHUT = 1, 0, -1, -2


@numba.njit(cache=True, nogil=True)
def _astar(  # type: ignore[no-untyped-def]
    packed, lfloor, lbox, luse, fine, fdone, fbi, fbk,
    cpacked, fraction, cbox, cuse, blocked, bdone, bbi, bbk, zoned,
    h, ox, oy, gi0, gk0, nx, ny, offsets, src, dst, lam, dropped,
):  # fmt: skip
    """``(status, node chain source first, cost, nodes expanded)``; status ``_FOUND`` or why not.

    Node ``(i, j)`` is lattice node ``(gi0 + i, gk0 + j)`` at ``(ox + (gi0 + i) h,
    oy + (gk0 + j) h)``.  ``fine`` holds the levels at ``h / 2`` (its ``[0, 0]`` is
    half-cell point ``(fbi, fbk)``), ``blocked`` the cores at ``h / 4`` (from
    ``(bbi, bbk)``); tiles not yet ``done`` are filled when first needed.
    ``zoned`` holds the keep-out zones at ``h / 4`` over this search's nodes
    alone (its ``[0, 0]`` is node ``(0, 0)``), or is empty when none are in force.
    """
    empty = np.zeros(0, dtype=np.int64)
    fx, fy = fine.shape
    bx, by = blocked.shape
    hh, hq = 0.5 * h, 0.25 * h
    for s, code in ((src, _SOURCE_SHUT), (dst, _TARGET_SHUT)):
        bi, bk = 4 * (gi0 + s // ny) - bbi, 4 * (gk0 + s % ny) - bbk
        if not bdone[bi // TILE, bk // TILE]:
            fill_cores(cpacked, cbox, cuse, hq, ox, oy, fraction, blocked, bbi, bbk, bi // TILE, bk // TILE)
            bdone[bi // TILE, bk // TILE] = True
        if blocked[bi, bk] or (zoned.size and zoned[4 * (s // ny), 4 * (s % ny)]):
            return code, empty, math.inf, 0
    n = nx * ny
    g = np.full(n, math.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    gxx, gyy = ox + (gi0 + dst // ny) * h, oy + (gk0 + dst % ny) * h
    cap = 1024
    hkey = np.empty(cap)
    hval = np.empty(cap, dtype=np.int64)
    size = 0
    g[src] = 0.0
    hkey[0] = _HEURISTIC * math.hypot(gxx - ox - (gi0 + src // ny) * h, gyy - oy - (gk0 + src % ny) * h)
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
        for ti in range(max(0, fi - 4) // TILE, min(fx - 1, fi + 4) // TILE + 1):
            for tk in range(max(0, fj - 4) // TILE, min(fy - 1, fj + 4) // TILE + 1):
                if not fdone[ti, tk]:
                    fill_level(packed, lbox, luse, hh, ox, oy, lfloor, fine, fbi, fbk, ti, tk)
                    fdone[ti, tk] = True
        for ti in range(max(0, qi - 8) // TILE, min(bx - 1, qi + 8) // TILE + 1):
            for tk in range(max(0, qj - 8) // TILE, min(by - 1, qj + 8) // TILE + 1):
                if not bdone[ti, tk]:
                    fill_cores(cpacked, cbox, cuse, hq, ox, oy, fraction, blocked, bbi, bbk, ti, tk)
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
            if zoned.size and (
                zoned[4 * ti, 4 * tj]
                or zoned[4 * i + di, 4 * j + dj]
                or zoned[4 * i + 2 * di, 4 * j + 2 * dj]
                or zoned[4 * i + 3 * di, 4 * j + 3 * dj]
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
            key = cost + _HEURISTIC * math.hypot(gxx - ox - (gi0 + ti) * h, gyy - oy - (gk0 + tj) * h)
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
    if not cell_m > 0:
        return None
    k, h = cell_ladder(cell_m)
    (x0, y0), (x1, y1) = box
    ox = oy = 0.0
    gi0, gk0 = math.ceil(x0 / h), math.ceil(y0 / h)  # inward: never past the asked box (or the bounds)
    nx = max(2, math.floor(x1 / h) - gi0 + 1)
    ny = max(2, math.floor(y1 / h) - gk0 + 1)
    if cores.zones:  # the very grid ``GridGraph(field, box, cores=cores, cell_m=cell_m)`` builds
        h, ox, oy, gi0, gk0 = cell_m, x0, y0, 0, 0
        nx, ny = max(2, math.ceil((x1 - x0) / h) + 1), max(2, math.ceil((y1 - y0) / h) + 1)

    def node(x: float, y: float) -> int:
        i = min(max(round((x - ox) / h) - gi0, 0), nx - 1)
        j = min(max(round((y - oy) / h) - gk0, 0), ny - 1)
        return int(i * ny + j)

    src, dst = node(*source), node(*goal)
    packed = np.ascontiguousarray(field.packed)
    peak = float(np.max(packed[:, kernels.SCALE])) if len(field) else 0.0
    if peak <= 0:
        packed = np.zeros((0, len(kernels.PACKED_COLUMNS)))
    lfloor = LEVEL_FLOOR * peak
    # with zones, this search's own lattice (on the grid's nodes, which no other search shares)
    lat = (
        kept_lattice(field, cores, packed, lfloor, k, h)
        if not cores.zones
        else Lattice(packed, lfloor, cores, h, (ox, oy))
    )
    if not lat.cover(gi0, gk0, nx, ny):  # too big to keep: this search's own
        lat = Lattice(packed, lfloor, cores, h, (ox, oy))
        if not lat.cover(gi0, gk0, nx, ny):  # past any lattice's cap: the kernel would write outside it
            return None
    cpacked = np.ascontiguousarray(cores.packed)
    # the zones on this search's own quarter lattice, by the rule ``Cores.raster`` applies to a grid's
    q = 0.25 * h
    zoned = np.zeros((0, 0), dtype=np.bool_)
    if cores.zones:
        zoned = cores.zones.raster(
            (ox, oy), q, (4 * nx - 3, 4 * ny - 3), ZONE_RASTER_SPACINGS * q + cores.zone_margin_m
        )
    dropped: list[tuple[int, int]] = []
    expanded = 0
    for attempt in range(repairs + 1):
        status, chain, cost, work = _astar(
            packed, lfloor, lat.lbox, lat.luse, lat.fine, lat.fdone, lat.fbase[0], lat.fbase[1],
            cpacked, float(cores.fraction), lat.cbox, lat.cuse, lat.blocked, lat.bdone, lat.bbase[0], lat.bbase[1], zoned,
            h, ox, oy, gi0, gk0, nx, ny, _OFFSETS, src, dst, float(lam),
            np.array(dropped, dtype=np.int64).reshape(-1, 2),
        )  # fmt: skip
        expanded += work
        if status != _FOUND:
            return None
        pts = np.stack([ox + (gi0 + chain // ny) * h, oy + (gk0 + chain % ny) * h], axis=1)
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
    if cores.zones:  # as the grid's walk, every node to the shortcut: the grid's very route
        corners = np.arange(len(chain))
    return LazyRoute(chain, pts, float(cost), expanded, attempt + 1, corners.astype(np.int64))
