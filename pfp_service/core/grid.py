"""A weighted grid graph over a threat field, for shortest paths by Dijkstra.

Nodes sit on a regular grid of ``cell_m``.  Each edge carries its length and
its exposure (the integral of the weighted threat level along it, Simpson's
rule on its ends and midpoint), so one graph serves every ``lambda`` of the
cost ``length + lambda * exposure``.  Connectivity is 8 (king moves) or 16
(king and knight moves; the longest heading error is then 13.3 degrees instead
of 22.5).  Nodes inside a threat core, and edges whose midpoint is, can be
left out, which makes "is there a way that avoids every core?" a question of
graph connectivity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from pfp_service.core.cores import Cores
from pfp_service.core.threat import ThreatField

__all__ = ["GridGraph", "Route"]

_KING = ((1, 0), (0, 1), (1, 1), (1, -1))
_KNIGHT = ((2, 1), (1, 2), (2, -1), (1, -2))


@dataclass(frozen=True, slots=True)
class Route:
    """A node path through the grid and its cost, or ``points`` empty when none exists."""

    points: np.ndarray  # (K, 2) node coordinates, source first
    cost: float


class GridGraph:
    """The grid over ``((xmin, ymin), (xmax, ymax))`` with at most ``cells`` cells along the longer side.

    Args:
        field: the threats.
        box: the area covered, in metres.
        cells: resolution along the longer side.
        connectivity: 8 or 16.
        cores: when given, nodes and edge midpoints inside a core are left out.
    """

    def __init__(
        self,
        field: ThreatField,
        box: tuple[tuple[float, float], tuple[float, float]],
        cells: int = 200,
        connectivity: int = 16,
        cores: Cores | None = None,
    ) -> None:
        (x0, y0), (x1, y1) = box
        span = max(x1 - x0, y1 - y0)
        self.cell_m = h = span / cells if span > 0 else 1.0
        self.nx = nx = max(2, math.ceil((x1 - x0) / h) + 1)
        self.ny = ny = max(2, math.ceil((y1 - y0) / h) + 1)
        self.origin = (x0, y0)
        gx, gy = np.meshgrid(x0 + h * np.arange(nx), y0 + h * np.arange(ny), indexing="ij")
        self.nodes = np.stack([gx.ravel(), gy.ravel()], axis=1)
        level = field.level(self.nodes) if len(field) else np.zeros(nx * ny)
        self.open = ~cores.inside(self.nodes) if cores is not None else np.ones(nx * ny, dtype=bool)
        offsets = _KING + (_KNIGHT if connectivity == 16 else ())
        src, dst, length, exposure = [], [], [], []
        idx = np.arange(nx * ny).reshape(nx, ny)
        for di, dj in offsets:
            a = idx[max(0, -di) : nx - max(0, di), max(0, -dj) : ny - max(0, dj)].ravel()
            b = a + di * ny + dj
            keep = self.open[a] & self.open[b]
            a, b = a[keep], b[keep]
            mid = 0.5 * (self.nodes[a] + self.nodes[b])
            if cores is not None and len(mid):
                ok = ~cores.inside(mid)
                a, b, mid = a[ok], b[ok], mid[ok]
            lm = field.level(mid) if len(field) else np.zeros(len(a))
            ln = h * math.hypot(di, dj)
            src.append(a)
            dst.append(b)
            length.append(np.full(len(a), ln))
            exposure.append(ln * (level[a] + 4.0 * lm + level[b]) / 6.0)
        self._src = np.concatenate(src)
        self._dst = np.concatenate(dst)
        self.edge_length = np.concatenate(length)
        self.edge_exposure = np.concatenate(exposure)

    def nearest(self, x: float, y: float) -> int:
        """The open node nearest to ``(x, y)``, or -1 if no node is open."""
        i = min(max(round((x - self.origin[0]) / self.cell_m), 0), self.nx - 1)
        j = min(max(round((y - self.origin[1]) / self.cell_m), 0), self.ny - 1)
        k = i * self.ny + j
        if self.open[k]:
            return int(k)
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
        n = len(self.nodes)
        w = self.edge_length + lam * self.edge_exposure
        graph = csr_matrix((w, (self._src, self._dst)), shape=(n, n))
        dist, pred = dijkstra(graph, directed=False, indices=target, return_predecessors=True)
        return dist, pred

    def route(self, source: int, target: int, lam: float) -> Route:
        """The cheapest node path from ``source`` to ``target`` (empty if they are not connected)."""
        if source < 0 or target < 0:
            return Route(np.zeros((0, 2)), math.inf)
        dist, pred = self.cost_to(target, lam)
        if not math.isfinite(dist[source]):
            return Route(np.zeros((0, 2)), math.inf)
        chain = [source]
        while chain[-1] != target:
            chain.append(int(pred[chain[-1]]))
        return Route(self.nodes[chain], float(dist[source]))
