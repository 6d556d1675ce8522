"""A weighted grid graph over a threat field, for shortest paths by Dijkstra.

Nodes sit on a regular grid of ``cell_m``.  Each edge carries its length and
its exposure (the integral of the weighted threat level along it, Simpson's
rule on its ends and midpoint), so one graph serves every ``lambda`` of the
cost ``length + lambda * exposure``.  Connectivity is 8 (king moves) or 16
(king and knight moves; the longest heading error is then 13.3 degrees instead
of 22.5).  Nodes inside a threat core, and edges that meet one at a midpoint
or quarter point, can be left out, which makes "is there a way that avoids
every core?" a question of graph connectivity.

A node path is then smoothed by ``polylines.shortcut``: a run of grid edges
becomes one straight segment whenever that costs no more ``J`` (and, given
cores, enters none), which removes the grid's heading quantisation.
``polylines.resample`` spaces a polyline evenly again, for a stepper to follow.
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
from pfp_service.core.threat import LEVEL_FLOOR, ThreatField

__all__ = ["GridGraph", "Route"]

_KING = ((1, 0), (0, 1), (1, 1), (1, -1))
_KNIGHT = ((2, 1), (1, 2), (2, -1), (1, -2))
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
