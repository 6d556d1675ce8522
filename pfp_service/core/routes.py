"""Shared route searches: one cost-to-go field per goal and world version, walked by every unit going there.

A route search (``escape_strategies.global_route``) is one Dijkstra run *from
the goal* over a local grid (``grid.GridGraph.cost_to``): the cost-to-go from
every node and the next node towards the goal.  Any unit inside that grid then
gets its route by walking predecessors, so ``RouteCache`` keeps the searches
and hands them out.  A platoon of 200 units with one objective costs one
search per world version, not 200 (two the first time its goal is seen).

Keys.  A search is kept under ``(field, goal, lambda, bounds)``.  A
``ThreatField`` is immutable and replaced on every world change, so the field
*is* the world version: a new field never meets an old field's search.  The
key holds the field by a weak reference, which equals another only while both
fields live (identity), so a gone field's key never matches a new field's.

Box and cell.  A request (``Ask``) names the box and the cell its own search
would use (``route_cell``).  A lone unit's miss (its goal not known to be
shared) builds no grid: A* (``astar.lazy_route``) searches from the unit to
the goal on the field's lattice at the cell at or just under the asked one
(``astar.cell_ladder``), filling levels and cores only where it looks and
keeping them for the next lone search under the field (keep-out zones are
rastered per search); it falls back to the tight grid (used for that ask and
not kept) where A* does not apply (a unit or goal in a core or a zone, no path).  Once a goal is known to be shared (a second unit, by
``Ask.unit``, asked for it under this field or an earlier one) a miss builds a
grid for everyone: ``ROOM`` of the box's span to spare on every side, so the
rest of the group lands inside it, at ``1 / REFINE`` of the asked cell, since
the search is paid once; within ``ROOM_MAX_NODES`` (refinement, then room, is
given up to stay under it).  It serves any unit whose own box it covers at a
cell at most ``1 + CELL_SLACK`` times the unit's own: the cell rule's
span-derived part is a cost cap rather than a resolution a route needs, and
its threat-derived part (a sixth of the narrowest sigma, 3.5 sigma at most) is
the same for every unit under one field.  A platoon thus pays two searches the
first time its goal is seen (the first unit's own, then the shared one) and
one per world change after that.

Shortcut tails.  ``polylines.shortcut`` is greedy and forward-looking: what it keeps
from a node on depends only on the node path from there to the goal, which is
the same for every unit whose walk passes that node.  Each kept grid remembers,
per kept node, the shortcut polyline from it to the goal; a later walk stops at
the first such node, shortcuts only its own prefix and appends the tail.
Every segment is still either a grid edge checked against the cores or a
straight shortcut that costs no more ``J`` and enters no core.

Bounds.  At most ``max_entries`` grids and ``max_nodes`` nodes in all (LRU:
the least recently used grid goes first; a single grid over ``max_nodes`` is
used once and not kept); grids of fields that have gone are dropped on the
next insert, and at most ``MAX_SLOTS`` (field, goal) keys are remembered.
``RouteCache(max_entries=0)`` keeps nothing and builds every search tight: one
search per request, as before this module.

Owners.  A cache has one owner at a time and takes no lock (the core does
no concurrency): the planning loop, or a worker process, each of which runs
one search at a time.  Processes share nothing: each worker process has its
own ``ROUTES``, so a pool pays the searches once per goal and worker; send a
group's jobs to one worker where that matters.  Code that shares one cache
between threads holds its own lock around every call.
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from pfp_service.core.astar import lazy_route
from pfp_service.core.cores import Cores
from pfp_service.core.grid import GridGraph, Route
from pfp_service.core.metrics import LAMBDA, path_cost
from pfp_service.core.polylines import resample, shortcut_kept
from pfp_service.core.threat import ThreatField

__all__ = [
    "CELL_SLACK",
    "GLOBAL_CELLS",
    "ROOM",
    "ROUTES",
    "Ask",
    "Found",
    "RouteCache",
    "RouteStats",
    "route_cell",
    "wary_tie",
]

Box = tuple[tuple[float, float], tuple[float, float]]

GLOBAL_CELLS = 100  # the coarsest route search: cells along the longer side
ROUTE_MAX_CELLS = 300
SIGHT_CELLS = 1.0  # over a masked field, a route search's cell is at most this many visibility window cells
WARY_LAMBDA = 2.0  # over a masked field, a second route search prices exposure this much more ...
WARY_CELL = 3.0  # ... on cells this much coarser (it is only asked whether a less exposed way ties) ...
WARY_MARGIN = 0.01  # ... and wins a tie: its J at most this much above the first's, and less exposed
ROOM = 0.25  # a shared goal's grid: this share of the asked box's span to spare on every side
REFINE = 2.0  # a shared goal's grid: its cell this much finer than the asked one (the search is paid once)
CELL_SLACK = 0.25  # a kept grid's cell may be this much coarser than the asked one
ROOM_MAX_NODES = 160_000  # a shared goal's grid stays under this (or the asked grid's size): ~50 MB
MAX_ENTRIES = 16
MAX_NODES = 500_000  # ~300 B a node with its edges: ~150 MB of kept grids a process at most
_MAX_TAILS = 4096  # shortcut tails remembered per grid
_SHARED_GOALS = 1024  # goals remembered as shared, across fields
MAX_SLOTS = 4096  # (field, goal) keys remembered, with who asked
_REPAIRS = 8  # as grid.GridGraph.route: searches after dropping edges that clip a core
_EPS = 1e-9


@dataclass(frozen=True, slots=True)
class Ask:
    """One unit's route request: what its own search would be.

    Attributes:
        field: the threats (the world version).
        cores: the cores the grid leaves out (``Cores.of(field, SEARCH_FRACTION)``).
        source: the unit, in metres.
        goal: the goal, in metres.
        lam: ``lambda`` of the cost ``length + lambda * exposure``.
        box: the area its own search would cover.
        cell_m: the cell its own search would use.
        bounds: the mission bounds (a grid never reaches past them), if any.
        unit: which unit asks (``Stepper.unit_key``): a goal asked for by two
            units is shared, one unit asking again from elsewhere is not.
    """

    field: ThreatField
    cores: Cores
    source: tuple[float, float]
    goal: tuple[float, float]
    lam: float
    box: Box
    cell_m: float
    bounds: Box | None = None
    unit: int = 0


@dataclass(frozen=True, slots=True)
class Found:
    """The answer to an ``Ask``.

    Attributes:
        route: the node path from the unit's nearest open node to the goal's,
            or to the first node a remembered tail goes on from (``points``
            empty when there is none; ``sealed`` and ``walled`` as
            ``GridGraph.walk`` says).
        grid: the grid it was walked on (shared: read, never change it); ``None``
            when A* found the route without building one (a lone unit's).
        polyline: when there is a route, the whole way from ``source`` to the
            goal, shortcut (not resampled); else empty.
        shared: the grid had been searched before this ask (a hit).
    """

    route: Route
    grid: GridGraph | None
    polyline: np.ndarray
    shared: bool


@dataclass(frozen=True, slots=True)
class RouteStats:
    """A snapshot of a cache's counters.

    Attributes:
        searches: Dijkstra runs, a repair's included (one per grid built, plus repairs).
        hits: asks served by a kept grid.
        misses: asks that built a grid.
        tails: walks that ended on a remembered shortcut tail.
        evictions: grids dropped to keep the bounds (or because their field went).
        entries: grids kept now.
        nodes: their nodes in all.
        lazy: asks of a lone unit answered by A* (``astar.lazy_route``), with no grid built.
        expanded: the nodes those A* searches expanded, in all.
    """

    searches: int
    hits: int
    misses: int
    tails: int
    evictions: int
    entries: int
    nodes: int
    lazy: int = 0
    expanded: int = 0


class _Entry:
    """One searched grid: a cost-to-go to one goal under one field."""

    __slots__ = ("box", "cell_m", "dist", "field", "generation", "grid", "kept", "pred", "tails", "target")

    def __init__(self, field: ThreatField, grid: GridGraph, box: Box, target: int, lam: float) -> None:
        self.field = weakref.ref(field)
        self.grid = grid
        self.box = box
        self.cell_m = grid.cell_m
        self.target = target
        none = (np.full(len(grid.nodes), np.inf), np.full(len(grid.nodes), -9999, dtype=np.int32))
        self.dist: np.ndarray
        self.pred: np.ndarray
        self.dist, self.pred = grid.cost_to(target, lam) if target >= 0 else none
        self.tails: dict[int, np.ndarray] = {}  # kept node -> shortcut polyline from it to the goal
        self.generation = 0  # bumped by a repair: tails computed before it are not stored
        self.kept = False  # in the cache (else used for one ask only)

    def serves(self, ask: Ask) -> bool:
        (ax0, ay0), (ax1, ay1) = ask.box
        (ex0, ey0), (ex1, ey1) = self.box
        tol = _EPS * max(1.0, abs(ex1 - ex0), abs(ey1 - ey0))
        covers = ex0 <= ax0 + tol and ey0 <= ay0 + tol and ex1 >= ax1 - tol and ey1 >= ay1 - tol
        fine = self.cell_m <= ask.cell_m * (1.0 + CELL_SLACK) * (1.0 + _EPS)
        return covers and fine


class _Slot:
    """The grids of one key, and who asked for it."""

    __slots__ = ("entries", "units")

    def __init__(self) -> None:
        self.entries: list[_Entry] = []
        self.units: set[int] = set()  # up to two: is the goal shared?


class RouteCache:
    """Cost-to-go searches kept per ``(field, goal, lambda, bounds)`` and shared by every unit that asks.

    Args:
        max_entries: grids kept at most (0: keep none, every ask searches tight).
        max_nodes: grid nodes kept at most, in all.
        room: a shared goal's grid: the share of the asked span to spare on every side.
    """

    def __init__(
        self, max_entries: int = MAX_ENTRIES, max_nodes: int = MAX_NODES, room: float = ROOM
    ) -> None:
        self.max_entries = max_entries
        self.max_nodes = max_nodes
        self.room = room if max_entries > 0 else 0.0
        self._slots: OrderedDict[tuple[object, ...], _Slot] = OrderedDict()  # (field ref, goal key): LRU
        self._lru: OrderedDict[int, tuple[_Slot, _Entry]] = OrderedDict()
        self._shared: OrderedDict[tuple[object, ...], None] = OrderedDict()
        self._nodes = 0
        self._searches = self._hits = self._misses = self._tails = self._evictions = 0
        self._lazy = self._expanded = 0

    def stats(self) -> RouteStats:
        """The counters now."""
        return RouteStats(
            self._searches,
            self._hits,
            self._misses,
            self._tails,
            self._evictions,
            len(self._lru),
            self._nodes,
            self._lazy,
            self._expanded,
        )

    def clear(self) -> None:
        """Forget every kept grid (the counters stay)."""
        self._slots.clear()
        self._lru.clear()
        self._shared.clear()
        self._nodes = 0

    def find(self, ask: Ask) -> Found:
        """The route for ``ask``: from a kept search where one serves it, else from a new one.

        Returns:
            a ``Found``; no route is a value (``Found.route.points`` empty), never an exception.
        """
        goal_key = (ask.goal, ask.lam, ask.bounds, ask.cores.fraction)
        slot = self._slot(ask.field, goal_key)
        entry = min((e for e in slot.entries if e.serves(ask)), key=lambda e: e.cell_m, default=None)
        shared = entry is not None
        if entry is None:
            group = self._note(ask, slot, goal_key)
            if not group:  # a lone unit: A* over the same grid, touching only what it needs
                lazy = lazy_route(
                    ask.field, ask.box, ask.cores, ask.cell_m, ask.source, ask.goal, ask.lam, _REPAIRS
                )
                if lazy is not None:
                    self._misses += 1
                    self._searches += lazy.searches
                    self._lazy += 1
                    self._expanded += lazy.expanded
                    route = Route(lazy.points, lazy.cost, nodes=lazy.nodes)
                    # a straight run of grid edges is one segment to the shortcut (the same way, fewer points)
                    corners = lazy.corners
                    _, pts, tail = _joined(ask, lazy.nodes[corners], lazy.points[corners], None)
                    return Found(route, None, _shortcut(ask, pts, tail), False)
            entry = self._build(ask, slot, group)
        else:
            self._touch(entry)
        grid = entry.grid
        route = self._walk(entry, grid.nearest(*ask.source), ask.lam)
        if not len(route.points):
            return Found(route, grid, np.zeros((0, 2)), shared)
        assert route.nodes is not None
        chain = route.nodes  # to the goal's node, or to the first node with a tail
        generation = entry.generation
        ids, pts, tail = _joined(ask, chain, grid.nodes[chain], entry.tails.get(int(chain[-1])))
        kept = shortcut_kept(ask.field, pts, ask.lam, ask.cores)
        head = pts[kept]
        polyline = head if tail is None else np.concatenate([head, tail[1:]])
        if entry.kept:
            self._remember(slot, entry, generation, ids[kept], polyline, tail is not None)
        return Found(route, grid, polyline, shared)

    # -- inside -----------------------------------------------------------------------------
    def _slot(self, field: ThreatField, goal_key: tuple[object, ...]) -> _Slot:
        # a weak reference as the key: equal to another only while both fields live (so by identity),
        # and a gone field's key never equals a new field's, whatever its id
        key = (weakref.ref(field), *goal_key)
        slot = self._slots.get(key)
        if slot is None:
            slot = self._slots[key] = _Slot()
            while len(self._slots) > MAX_SLOTS:  # the least recently asked goal goes, with its grids
                _, old = self._slots.popitem(last=False)
                for entry in old.entries:
                    self._drop(id(entry))
        self._slots.move_to_end(key)
        return slot

    def _note(self, ask: Ask, slot: _Slot, goal_key: tuple[object, ...]) -> bool:
        """Note who asks for this goal; is it shared (a second unit, now or under an earlier field)?"""
        if len(slot.units) < 2:
            slot.units.add(ask.unit)
        shared = len(slot.units) > 1 or goal_key in self._shared
        if shared:
            self._shared[goal_key] = None
            self._shared.move_to_end(goal_key)
            while len(self._shared) > _SHARED_GOALS:
                self._shared.popitem(last=False)
        return shared

    def _build(self, ask: Ask, slot: _Slot, shared: bool) -> _Entry:
        """A new search for ``ask``: tight, or with room when the goal is shared."""
        self._misses += 1
        box, cell = self._shape(ask) if shared and self.room > 0 else (ask.box, ask.cell_m)
        grid = GridGraph(ask.field, box, cores=ask.cores, cell_m=cell)
        entry = _Entry(ask.field, grid, box, grid.nearest(*ask.goal), ask.lam)
        self._searches += 1 if entry.target >= 0 else 0
        n = len(grid.nodes)
        if not shared or self.max_entries <= 0 or n > self.max_nodes:
            return entry  # used for this ask only: a lone unit's, or too big to keep
        entry.kept = True
        slot.entries.append(entry)
        self._lru[id(entry)] = (slot, entry)
        self._nodes += n
        self._evict()
        return entry

    def _shape(self, ask: Ask) -> tuple[Box, float]:
        """A shared goal's grid: the asked box with room on every side, at a finer cell, within the node cap.

        The options are tried in order, ``(ROOM, REFINE)`` first and the
        asked box and cell last; the first under ``max(ROOM_MAX_NODES, the
        asked grid's nodes)`` is taken.
        """
        (x0, y0), (x1, y1) = ask.box
        span = max(x1 - x0, y1 - y0)

        def nodes(pad: float, h: float) -> int:
            return (math.ceil((x1 - x0 + 2 * pad) / h) + 1) * (math.ceil((y1 - y0 + 2 * pad) / h) + 1)

        cap = max(ROOM_MAX_NODES, nodes(0.0, ask.cell_m))
        room, refine = self.room, REFINE
        options = ((room, refine), (room, math.sqrt(refine)), (room, 1.0), (room / 2, 1.0), (0.0, 1.0))
        room, refine = next((r, f) for r, f in options if nodes(r * span, ask.cell_m / f) <= cap)
        pad = room * span
        bx0, by0, bx1, by1 = x0 - pad, y0 - pad, x1 + pad, y1 + pad
        if ask.bounds is not None:
            (lx0, ly0), (lx1, ly1) = ask.bounds
            bx0, by0, bx1, by1 = max(bx0, lx0), max(by0, ly0), min(bx1, lx1), min(by1, ly1)
        return ((bx0, by0), (bx1, by1)), ask.cell_m / refine

    def _walk(self, entry: _Entry, source: int, lam: float) -> Route:
        """Down the entry's cost-to-go from ``source`` to the goal or a remembered tail's node.

        An edge of it that clips a core is dropped and the search run again
        (a tail's own edges were checked by the walk that made it).
        """
        grid = entry.grid
        for _ in range(_REPAIRS):
            route = grid.walk(source, entry.target, entry.dist, entry.pred, entry.tails)
            if not grid.drop_clipping(route):
                return route
            entry.dist, entry.pred = grid.cost_to(entry.target, lam)
            entry.tails.clear()
            entry.generation += 1
            self._searches += 1
        return grid.walk(source, entry.target, entry.dist, entry.pred, entry.tails)

    def _touch(self, entry: _Entry) -> None:
        self._hits += 1
        if id(entry) in self._lru:
            self._lru.move_to_end(id(entry))

    def _evict(self) -> None:
        """Drop grids of gone fields, then the least recently used, until within the bounds."""
        for key in [k for k, (_, e) in self._lru.items() if e.field() is None]:
            self._drop(key)
        while self._lru and (len(self._lru) > self.max_entries or self._nodes > self.max_nodes):
            self._drop(next(iter(self._lru)))

    def _drop(self, key: int) -> None:
        if key not in self._lru:
            return
        slot, entry = self._lru.pop(key)
        self._nodes -= len(entry.grid.nodes)
        self._evictions += 1
        slot.entries = [e for e in slot.entries if e is not entry]  # rebound: a reader's list stays whole

    def _remember(
        self, slot: _Slot, entry: _Entry, generation: int, ids: np.ndarray, polyline: np.ndarray, tailed: bool
    ) -> None:
        """Store the shortcut tail from each kept node of a walk (unless a repair came in between)."""
        if tailed:
            self._tails += 1
        if entry.generation != generation or len(entry.tails) >= _MAX_TAILS:
            return
        for k, node in enumerate(ids.tolist()):
            if node >= 0 and node not in entry.tails:
                entry.tails[int(node)] = polyline[k:]


def _joined(
    ask: Ask, chain: np.ndarray, nodes: np.ndarray, tail: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The way to shortcut: the unit, the chain's nodes, and the goal unless a tail goes on; repeats dropped.

    Returns ``(node ids, -1 for the unit and the goal; points; tail)``.
    """
    end = np.array([ask.goal]) if tail is None else np.zeros((0, 2))
    ids = np.concatenate([[-1], chain, np.full(len(end), -1)]).astype(np.int64)
    pts = np.concatenate([[ask.source], nodes, end])
    keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)])
    return ids[keep], pts[keep], tail


def _shortcut(ask: Ask, pts: np.ndarray, tail: np.ndarray | None) -> np.ndarray:
    head = pts[shortcut_kept(ask.field, pts, ask.lam, ask.cores)]
    return head if tail is None else np.concatenate([head, tail[1:]])


ROUTES = RouteCache()
"""The process's shared cache, used by ``escape_strategies.global_route`` unless it is given another."""


def route_cell(span_m: float, s_min_m: float, fine: bool = True, sight_m: float = math.inf) -> float:
    """Cell size of a route search over ``span_m``: fine enough for the narrowest threat, and its sight.

    Fine: a sixth of the narrowest standard deviation (so a gap a fraction of
    a standard deviation wide still holds grid nodes), at most ``span / 100``,
    no finer than ``span / ROUTE_MAX_CELLS``.  Coarse (``fine=False``): a third,
    and half the cells (at 100 cells the coarse route round wide thin pancakes
    cost up to 1.65 J*).  Either way never wider than 3.5 narrowest standard
    deviations, past which an edge's probe points could step over a core
    (then up to ``2 * ROUTE_MAX_CELLS``).  Over a masked field (``sight_m``,
    ``visibility.finest_cell``) at most ``SIGHT_CELLS`` window cells, before
    those floors: coarser, an edge's three samples straddle a seen patch.
    """
    most = ROUTE_MAX_CELLS if fine else ROUTE_MAX_CELLS // 2
    h = min(span_m / GLOBAL_CELLS, s_min_m / (6.0 if fine else 3.0), SIGHT_CELLS * sight_m)
    h = max(h, span_m / most)
    return max(min(h, 3.5 * s_min_m), span_m / (2 * ROUTE_MAX_CELLS))


def wary_tie(ask: Ask, corners: np.ndarray, step: float, cache: RouteCache) -> np.ndarray:
    """Over a masked field: ``corners``, or the route searched at ``WARY_LAMBDA`` times lambda if it ties on ``J``.

    A masked level steps from hidden to seen over a window cell, and a route
    grid prices it from a few samples an edge: two ways round a ridge can
    then differ in ``J`` by less than that pricing's error (``WARY_MARGIN``)
    and in exposure many times over (a gap between two threats' cores in
    view of one, against the ground behind them).  Both are priced as the
    unit will walk them (resampled at ``step``, Simpson on every piece); the
    less exposed wins such a tie, and only such a tie.  The search is the
    stepper's, so a preview and the live unit make the same choice.
    """
    a = resample(corners, step)
    ja = path_cost(a, ask.field, LAMBDA)
    la = float(np.hypot(*np.diff(a, axis=0).T).sum())
    if ja - la <= WARY_MARGIN * ja:  # its exposure is within a tie's margin of J: no tie could save more
        return corners
    wary = cache.find(dataclasses.replace(ask, lam=WARY_LAMBDA * ask.lam, cell_m=WARY_CELL * ask.cell_m))
    if not len(wary.polyline):
        return corners
    other = np.asarray(wary.polyline, dtype=np.float64)
    b = resample(other, step)
    jb = path_cost(b, ask.field, LAMBDA)
    lb = float(np.hypot(*np.diff(b, axis=0).T).sum())
    if jb <= (1.0 + WARY_MARGIN) * ja and jb - lb < ja - la:  # tied on J, and less exposed
        return other
    return corners
