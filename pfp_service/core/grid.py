"""A weighted grid graph over a threat field, for shortest paths by Dijkstra.

Nodes sit on a regular grid of ``cell_m``.  Each edge carries its length and
its exposure (the integral of the weighted threat level along it, Simpson's
rule on its ends and midpoint), so one graph serves every ``lambda`` of the
cost ``length + lambda * exposure``.  Connectivity is 8 (king moves) or 16
(king and knight moves; the longest heading error is then 13.3 degrees instead
of 22.5).  Nodes inside a threat core, and edges that meet one at a midpoint
or quarter point, can be left out, which makes "is there a way that avoids
every core?" a question of graph connectivity.

A node path is then smoothed by ``shortcut``: a run of grid edges becomes one
straight segment whenever that costs no more ``J`` (and, given cores, enters
none), which removes the grid's heading quantisation.  ``resample`` spaces a
polyline evenly again, for a stepper to follow.
"""

from __future__ import annotations

import math
from collections.abc import Container
from dataclasses import dataclass

import numba
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, dijkstra

from pfp_service.core import kernels
from pfp_service.core.cores import Cores
from pfp_service.core.cull import cell_level, index_of, point_level
from pfp_service.core.threat import LEVEL_FLOOR, ThreatField

__all__ = [
    "GridGraph",
    "Route",
    "polyline_clear",
    "resample",
    "segment_costs",
    "segment_hits",
    "shortcut",
    "shortcut_kept",
]

_KING = ((1, 0), (0, 1), (1, 1), (1, -1))
_KNIGHT = ((2, 1), (1, 2), (2, -1), (1, -2))
_WINDOW = 48  # grid edges a shortcut may replace at once
_SAMPLES = 17  # Simpson points on a candidate shortcut
_REPAIRS = 8  # route searches after dropping edges that clip a core


@dataclass(frozen=True, slots=True)
class Route:
    """A node path through the grid and its cost, or ``points`` empty when none exists."""

    points: np.ndarray  # (K, 2) node coordinates, source first
    cost: float
    sealed: bool = False  # no route, and a larger box would not help: the source or target is walled in
    walled: np.ndarray | None = None  # then: the walled-in component (a node mask) ...
    walled_side: str = ""  # ... and whose it is, "source" or "target"
    nodes: np.ndarray | None = None  # the node indices of ``points``


@numba.njit(cache=True, nogil=True)
def _edges(
    fine: np.ndarray, blocked: np.ndarray, check: bool, nx: int, ny: int, h: float, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every open edge, both ways, as CSR rows: ``(indptr, indices, length, Simpson exposure)``.

    ``fine`` holds the levels at half a cell, ``blocked`` (when ``check``) the
    cores at a quarter cell, so each edge's ends, midpoint and quarter points
    are lattice entries.
    """
    m = offsets.shape[0]
    cap = nx * ny * 2 * m
    indptr = np.zeros(nx * ny + 1, dtype=np.int64)
    indices = np.empty(cap, dtype=np.int32)
    length = np.empty(cap)
    exposure = np.empty(cap)
    n = 0
    for i in range(nx):
        for j in range(ny):
            src = i * ny + j
            if check and blocked[4 * i, 4 * j]:
                indptr[src + 1] = n
                continue
            for o in range(2 * m):
                sign = 1 if o < m else -1
                di, dj = sign * offsets[o % m, 0], sign * offsets[o % m, 1]
                ti, tj = i + di, j + dj
                if ti < 0 or ti >= nx or tj < 0 or tj >= ny:
                    continue
                if check and (
                    blocked[4 * ti, 4 * tj]
                    or blocked[4 * i + di, 4 * j + dj]
                    or blocked[4 * i + 2 * di, 4 * j + 2 * dj]
                    or blocked[4 * i + 3 * di, 4 * j + 3 * dj]
                ):
                    continue
                ln = h * math.sqrt(di * di + dj * dj)
                indices[n] = ti * ny + tj
                length[n] = ln
                exposure[n] = (
                    ln
                    * (fine[2 * i, 2 * j] + 4.0 * fine[2 * i + di, 2 * j + dj] + fine[2 * ti, 2 * tj])
                    / 6.0
                )
                n += 1
            indptr[src + 1] = n
    return indptr, indices[:n].copy(), length[:n].copy(), exposure[:n].copy()


class GridGraph:
    """The grid over ``((xmin, ymin), (xmax, ymax))`` with at most ``cells`` cells along the longer side.

    Levels come from one raster at half the cell size (``kernels.raster_level``:
    each threat only over its own box, terms below ``LEVEL_FLOOR`` of the
    strongest threat's peak left out), so nodes and every king and knight
    edge's midpoint are read off it and many small threats stay cheap.

    Args:
        field: the threats.
        box: the area covered, in metres.
        cells: resolution along the longer side (ignored when ``cell_m`` is given).
        connectivity: 8 or 16.
        cores: when given, nodes in a core are left out (``Cores.raster``, the
            cores' own rule), and so is every edge that meets a core at its
            midpoint or quarter points; at a cell under 3.7 narrowest standard
            deviations those points are closer than any core is wide, so no
            edge steps over one.
        cell_m: the cell size, instead of ``cells``.
    """

    def __init__(
        self,
        field: ThreatField,
        box: tuple[tuple[float, float], tuple[float, float]],
        cells: int = 200,
        connectivity: int = 16,
        cores: Cores | None = None,
        cell_m: float | None = None,
    ) -> None:
        (x0, y0), (x1, y1) = box
        span = max(x1 - x0, y1 - y0)
        if cell_m is not None and cell_m > 0:
            h = cell_m
        else:
            h = span / cells if span > 0 else 1.0
        self.cell_m = h
        self.nx = nx = max(2, math.ceil((x1 - x0) / h) + 1)
        self.ny = ny = max(2, math.ceil((y1 - y0) / h) + 1)
        self.origin = (x0, y0)
        gx, gy = np.meshgrid(x0 + h * np.arange(nx), y0 + h * np.arange(ny), indexing="ij")
        self.nodes = np.stack([gx.ravel(), gy.ravel()], axis=1)
        fine = np.zeros((2 * nx - 1, 2 * ny - 1))
        if len(field):
            peak = float(np.max(field.packed[:, kernels.SCALE]))
            if peak > 0:
                kernels.raster_level(field.packed, x0, y0, 0.5 * h, LEVEL_FLOOR * peak, fine)
        # cores on a lattice of a quarter cell: nodes, and each edge's quarter, mid and
        # three-quarter points, are all on it
        blocked = cores.raster((x0, y0), 0.25 * h, (4 * nx - 3, 4 * ny - 3)) if cores is not None else None
        self.open = ~blocked[::4, ::4].ravel() if blocked is not None else np.ones(nx * ny, dtype=bool)
        offsets = np.array(_KING + (_KNIGHT if connectivity == 16 else ()), dtype=np.int64)
        lattice = blocked if blocked is not None else np.zeros((1, 1), dtype=np.bool_)
        self._indptr, self._indices, self.edge_length, self.edge_exposure = _edges(
            fine, lattice, blocked is not None, nx, ny, h, offsets
        )
        self.cores = cores

    def cell_of(self, x: float, y: float) -> int:
        """The node nearest to ``(x, y)``, open or not (clamped to the box)."""
        i = min(max(round((x - self.origin[0]) / self.cell_m), 0), self.nx - 1)
        j = min(max(round((y - self.origin[1]) / self.cell_m), 0), self.ny - 1)
        return int(i * self.ny + j)

    def nearest(self, x: float, y: float) -> int:
        """The open node nearest to ``(x, y)``, or -1 if no node is open.

        Looked for in growing windows round ``(x, y)``: a window of half-width
        ``k`` cells holds every node within ``k`` cells, so an open node found
        that near is the nearest; the whole grid is scanned only past that.
        """
        fi = (x - self.origin[0]) / self.cell_m
        fj = (y - self.origin[1]) / self.cell_m
        i = min(max(round(fi), 0), self.nx - 1)
        j = min(max(round(fj), 0), self.ny - 1)
        k = i * self.ny + j
        if self.open[k]:
            return int(k)
        grid_open = self.open.reshape(self.nx, self.ny)
        w = 2
        while w < max(self.nx, self.ny):
            i0, i1, j0, j1 = max(i - w, 0), min(i + w + 1, self.nx), max(j - w, 0), min(j + w + 1, self.ny)
            oi, oj = np.nonzero(grid_open[i0:i1, j0:j1])
            if len(oi):
                d = np.hypot(
                    self.nodes[(oi + i0) * self.ny + oj + j0, 0] - x,
                    self.nodes[(oi + i0) * self.ny + oj + j0, 1] - y,
                )
                best = int(np.argmin(d))
                if d[best] <= (w - 0.5) * self.cell_m:  # nothing outside the window is nearer
                    return int((oi[best] + i0) * self.ny + oj[best] + j0)
            w *= 2
        opened = np.flatnonzero(self.open)
        if not len(opened):
            return -1
        d = np.hypot(self.nodes[opened, 0] - x, self.nodes[opened, 1] - y)
        return int(opened[int(np.argmin(d))])

    def cost_to(self, target: int, lam: float) -> tuple[np.ndarray, np.ndarray]:
        """Cost-to-go to node ``target`` from every node, and the next node towards it.

        The cost of an edge is ``length + lam * exposure``, i.e. the integral of
        ``1 + lam T`` along it.
        """
        dist, pred = dijkstra(
            self._graph(self.edge_length + lam * self.edge_exposure), indices=target, return_predecessors=True
        )
        return dist, pred

    def _graph(self, weights: np.ndarray) -> csr_matrix:
        """The graph with these edge weights (every edge is stored both ways, so it is directed)."""
        n = len(self.nodes)
        return csr_matrix((weights, self._indices, self._indptr), shape=(n, n))

    def _touches_border(self, nodes: np.ndarray) -> bool:
        """Does the node set (a boolean mask) include a node on the box's edge?"""
        m = nodes.reshape(self.nx, self.ny)
        return bool(m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())

    def _drop(self, pairs: list[tuple[int, int]]) -> None:
        """Remove the edges ``a - b`` (both ways) from the graph."""
        keep = np.ones(len(self._indices), dtype=bool)
        for a, b in pairs:
            for u, v in ((a, b), (b, a)):
                lo, hi = self._indptr[u], self._indptr[u + 1]
                keep[lo + np.flatnonzero(self._indices[lo:hi] == v)] = False
        rows = np.repeat(np.arange(len(self.nodes)), np.diff(self._indptr))
        counts = np.bincount(rows[keep], minlength=len(self.nodes))
        self._indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self._indices = self._indices[keep]
        self.edge_length = self.edge_length[keep]
        self.edge_exposure = self.edge_exposure[keep]

    def route(self, source: int, target: int, lam: float) -> Route:
        """The cheapest node path from ``source`` to ``target`` (empty if they are not connected).

        With cores, each edge of the path is then checked densely, as the
        judge checks a path (``Cores.segment_hits``); an edge that clips a
        core between its probe points (a skewed threat's sharp rear can be
        far thinner than its standard deviations) is dropped and the search
        run again, up to ``_REPAIRS`` times.
        """
        for _ in range(_REPAIRS):
            found = self._route(source, target, lam)
            if not self.drop_clipping(found):
                return found
        return self._route(source, target, lam)

    def drop_clipping(self, found: Route) -> bool:
        """Drop the edges of ``found`` that clip a core (``Cores.segment_hits``); were there any?

        After a drop every cost-to-go computed on this graph is stale: search again.
        """
        if self.cores is None or len(found.points) < 2:
            return False
        bad = np.flatnonzero(self.cores.segment_hits(found.points))
        if not len(bad):
            return False
        chain = found.nodes
        assert chain is not None
        self._drop([(int(chain[i]), int(chain[i + 1])) for i in bad])
        return True

    def _route(self, source: int, target: int, lam: float) -> Route:
        if source < 0 or target < 0:
            return Route(np.zeros((0, 2)), math.inf)
        dist, pred = self.cost_to(target, lam)
        return self.walk(source, target, dist, pred)

    def walk(
        self, source: int, target: int, dist: np.ndarray, pred: np.ndarray, stop: Container[int] = ()
    ) -> Route:
        """The node path from ``source`` down a cost-to-go to ``target`` (``cost_to(target, ...)``).

        The path ends early at the first node in ``stop`` (``cost`` is still
        the whole way's).  With no path, ``Route.sealed`` says whether a
        larger box could not help: the target's or the source's component
        misses the box's edge.
        """
        if source < 0 or target < 0:
            return Route(np.zeros((0, 2)), math.inf)
        if not math.isfinite(dist[source]):
            comp = np.isfinite(dist)
            if not self._touches_border(comp):
                return Route(np.zeros((0, 2)), math.inf, True, comp, "target")
            seen = breadth_first_order(self._graph(self.edge_length), source, return_predecessors=False)
            comp = np.zeros(len(self.nodes), dtype=bool)
            comp[seen] = True
            if not self._touches_border(comp):
                return Route(np.zeros((0, 2)), math.inf, True, comp, "source")
            return Route(np.zeros((0, 2)), math.inf)
        chain = [source]
        while chain[-1] != target and chain[-1] not in stop:
            chain.append(int(pred[chain[-1]]))
        return Route(self.nodes[chain], float(dist[source]), nodes=np.array(chain))

    @property
    def nbytes(self) -> int:
        """Memory held by the graph's arrays."""
        arrays = (self.nodes, self.open, self._indptr, self._indices, self.edge_length, self.edge_exposure)
        return sum(a.nbytes for a in arrays)


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
