"""The ways out of a trap, as one registry: ``STRATEGIES``, in ``auto``'s order.

A strategy looks at a ``Trap`` (where the unit is stuck, under which field)
and yields candidate polylines from the trap point to an *exit*, the point
where plain descent takes over again, cheapest candidate first.  It never
moves a unit: ``escape.Escaper`` judges each candidate (no threat core, and
descent from the exit must get clearly closer to the goal) and commits to the
first one that passes.  A strategy with no candidate at all yields
``NoCandidate(reason)`` and stops.

Each entry is a ``Strategy(name, tier, propose)``, its name also in the light
``options.ESCAPE_STRATEGIES`` (``escape`` checks they agree); ``auto``'s order
and its tiers are read from this registry.  ``auto`` asks every strategy of the
lowest tier, and only pays for a higher tier when that finds nothing
acceptable (tier 0: cheap, reactive; tier 1: a search).

* ``delta``: the paper's first remedy, descent with the goal weight raised
  x4, x16, x64.
* ``random``: the paper's second, a seeded random heading held for
  ``3 * trap_window`` steps (eight headings at most).
* ``waypoint``: the paper's third, descent towards an intermediate point
  beside the local threat cluster (1, 2 and 3 cluster radii out, at 45, 90
  and 135 degrees either side of the goal bearing).
* ``contour``: follow the iso-threat line through the trap, on the side with
  lower threat ahead, until clearly closer to the goal; if the line closes on
  itself, raise its level x1.5 and go on (never into a core).
* ``global``: Dijkstra cost-to-go, cost ``1 + lambda T``, on a local grid with
  the cores left out, shortcut where that costs no more; the route is cut at
  the first exit from which descent works (``global_route`` is the whole of
  it, which ``auto`` follows when the stepper foresees a trap).  Units with
  one goal under one field share its search (``routes.RouteCache``).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from types import MappingProxyType

import numba
import numpy as np

from pfp_service.core import kernels, polylines, steprule
from pfp_service.core.cores import SEARCH_FRACTION, Cores
from pfp_service.core.grid import GridGraph
from pfp_service.core.metrics import LAMBDA
from pfp_service.core.routes import GLOBAL_CELLS, ROUTES, Ask, RouteCache, route_cell, wary_tie
from pfp_service.core.threat import ThreatField
from pfp_service.core.visibility import finest_cell

__all__ = [
    "AUTO_ORDER",
    "GLOBAL_CELLS",
    "STRATEGIES",
    "Candidate",
    "NoCandidate",
    "Strategy",
    "Trap",
    "global_corners",
    "global_route",
    "rollout",
    "route_cell",
]

_MAX_RAISES = 6  # x1.5 each: up to 11x the trap's level
_MAX_EXITS = 4
Bounds = tuple[tuple[float, float], tuple[float, float]]


@dataclass(frozen=True, slots=True)
class NoCandidate:
    """A strategy's answer when it has no way out to offer, and why."""

    reason: str


Candidate = np.ndarray | NoCandidate


@numba.njit(cache=True, nogil=True)
def _rollout(
    packed: np.ndarray,
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    unit: np.ndarray,
    x: float,
    y: float,
    out: np.ndarray,
) -> int:
    out[0, 0] = x
    out[0, 1] = y
    n = 1
    for _ in range(out.shape[0] - 1):
        fx, fy, _lv, norm = kernels.point_descent(
            packed, x, y, unit[steprule.GOAL_X], unit[steprule.GOAL_Y], unit[steprule.GAIN]
        )
        code, _dx, _dy, _dist, _move, x, y = steprule.judge_zoned(
            unit, edges, offsets, circles, boxes, x, y, fx, fy, norm
        )
        if code != steprule.GO:
            break
        out[n, 0] = x
        out[n, 1] = y
        n += 1
    return n


def rollout(
    field: ThreatField,
    start: tuple[float, float],
    target: tuple[float, float],
    gain: float,
    step: float,
    tol: float,
    n: int,
) -> np.ndarray:
    """Simulated plain descent: at most ``n`` steps from ``start`` towards ``target`` (stops within ``tol``).

    Each step is ``steprule.judge``'s, unwatched and unbounded: the last one
    ends on ``target`` when it is within a step.
    """
    out = np.empty((n + 1, 2))
    unit = steprule.unit(target, gain, tol, step, watch=False)
    k = _rollout(field.packed, *field.zones.packed(), unit, float(start[0]), float(start[1]), out)
    return out[:k]


@dataclass(slots=True)
class Trap:
    """Everything a strategy may use about one trap."""

    field: ThreatField
    cores: Cores
    x: float
    y: float
    goal: tuple[float, float]
    delta: float
    gain: float
    step: float
    tolerance: float
    trap_window: int
    dist: float  # distance to the goal at the trap
    margin: float  # "clearly closer": the exit must be this much nearer the goal
    budget: int  # most points an escape polyline may have
    bounds: Bounds | None
    rng: np.random.Generator
    unit_key: int = 0  # which unit: units with one goal share its route search (``routes``)

    def cut(self, poly: np.ndarray) -> np.ndarray:
        """``poly`` up to its first point clearly closer to the goal than the trap."""
        d = np.hypot(poly[:, 0] - self.goal[0], poly[:, 1] - self.goal[1])
        hit = np.flatnonzero(d <= self.dist - self.margin)
        return poly[: hit[0] + 1] if len(hit) else poly

    def cluster_radius(self) -> float:
        """Size of the threat cluster around the trap: farthest reach of nearby threats."""
        best = 0.0
        nearest = (math.inf, 0.0)
        for t in self.field.threats:
            s = t.spread()
            d = math.hypot(t.xi[0] - self.x, t.xi[1] - self.y)
            nearest = min(nearest, (d, d + 2.0 * s))
            if d < 4.0 * s:
                best = max(best, d + 2.0 * s)
        return best if best > 0 else (nearest[1] if math.isfinite(nearest[0]) else 10.0 * self.step)


def _delta(tr: Trap) -> Iterator[Candidate]:
    for factor in (4.0, 16.0, 64.0):
        yield tr.cut(
            rollout(tr.field, (tr.x, tr.y), tr.goal, tr.gain * factor, tr.step, tr.tolerance, tr.budget)
        )


def _random(tr: Trap) -> Iterator[Candidate]:
    m = 3 * tr.trap_window
    k = np.arange(m + 1)[:, None] * tr.step
    gb = math.atan2(tr.goal[0] - tr.x, tr.goal[1] - tr.y)  # relative to the goal: rotation-equivariant
    for _ in range(8):
        b = gb + tr.rng.uniform(0.0, 2.0 * math.pi)
        yield np.array([tr.x, tr.y]) + k * np.array([math.sin(b), math.cos(b)])


def _waypoint(tr: Trap) -> Iterator[Candidate]:
    r0 = tr.cluster_radius()
    gb = math.atan2(tr.goal[0] - tr.x, tr.goal[1] - tr.y)  # compass bearing of the goal
    for r in (r0, 2.0 * r0, 3.0 * r0):
        for off in (45.0, -45.0, 90.0, -90.0, 135.0, -135.0):
            b = gb + math.radians(off)
            wp = (tr.x + r * math.sin(b), tr.y + r * math.cos(b))
            n = min(tr.budget, int(4.0 * r / tr.step) + tr.trap_window)
            yield rollout(tr.field, (tr.x, tr.y), wp, tr.delta / (r * r), tr.step, tr.tolerance, n)


def _settle(tr: Trap) -> tuple[float, float]:
    """Where the trap's descent comes to rest, found at finer and finer steps, within a step of the trap.

    Descent is judged trapped where it oscillates, about a step from the
    potential's minimum, so that point's level moves with the step; the
    minimum's does not (``pfp bench convergence``).  Bounded: at most
    ``_SETTLE_HALVINGS`` x ``_SETTLE_STEPS`` evaluations, each lowering the potential.
    """
    f, gain, (gx0, gy0) = tr.field, tr.gain, tr.goal

    def potential(x: float, y: float) -> tuple[float, float, float]:
        lv, hx, hy = f.level_grad_at(x, y)
        dx, dy = x - gx0, y - gy0
        return lv + gain * (dx * dx + dy * dy), hx + 2.0 * gain * dx, hy + 2.0 * gain * dy

    x, y = tr.x, tr.y
    here, fx, fy = potential(x, y)
    s = 0.5 * tr.step
    for _ in range(_SETTLE_HALVINGS):
        for _ in range(_SETTLE_STEPS):
            norm = math.hypot(fx, fy)
            if not norm > 0.0:
                return x, y
            nx, ny = x - s * fx / norm, y - s * fy / norm
            if math.hypot(nx - tr.x, ny - tr.y) > tr.step:
                break  # not the oscillation's own minimum: a creep, which goes on past it
            there, gx, gy = potential(nx, ny)
            if not there < here:
                break
            x, y, here, fx, fy = nx, ny, there, gx, gy
        s *= 0.5
    return x, y


_SETTLE_HALVINGS = 6  # to a 128th of the step
_SETTLE_STEPS = 8


def _contour(tr: Trap) -> Iterator[Candidate]:
    f = tr.field
    sx, sy = _settle(tr)
    level, gx, gy = f.level_grad_at(sx, sy)
    g = math.hypot(gx, gy)
    if not (level > 0.0 and g * tr.step > 1e-9 * level):
        yield NoCandidate("no threat slope at the trap to follow")
        return
    step = tr.step
    ahead = []
    for sign in (1.0, -1.0):
        tx, ty = -sign * gy / g, sign * gx / g
        probe = f.level_grad_at(sx + 3 * step * tx, sy + 3 * step * ty)[0]
        toward = tx * (tr.goal[0] - sx) + ty * (tr.goal[1] - sy)
        ahead.append((probe, -toward, sign))
    sign = min(ahead)[2]
    tx, ty = -sign * gy / g, sign * gx / g
    x, y, c = sx, sy, level
    pts = [(tr.x, tr.y), (x, y)] if (x, y) != (tr.x, tr.y) else [(x, y)]
    lx, ly, away, raises, exits, closer = x, y, False, 0, 0, False
    while len(pts) < tr.budget:
        qx, qy = x + step * tx, y + step * ty
        for _ in range(3):  # pull back onto the level set, by at most one step
            lv, hx, hy = f.level_grad_at(qx, qy)
            h2 = hx * hx + hy * hy
            if h2 == 0.0:
                break
            k = max(-step, min(step, (lv - c) / math.sqrt(h2)))
            qx, qy = qx - k * hx / math.sqrt(h2), qy - k * hy / math.sqrt(h2)
        lv, hx, hy = f.level_grad_at(qx, qy)
        h = math.hypot(hx, hy)
        if h == 0.0:
            yield NoCandidate("the contour fades out (no threat slope)")
            return
        nx, ny = -hy / h, hx / h
        if nx * tx + ny * ty < 0:
            nx, ny = -nx, -ny
        x, y, tx, ty = qx, qy, nx, ny
        pts.append((x, y))
        if tr.cores.inside(np.array([[x, y]]))[0]:
            yield NoCandidate(f"the contour reaches a threat core at level {c:.3g} without an exit")
            return
        was, closer = closer, math.hypot(tr.goal[0] - x, tr.goal[1] - y) <= tr.dist - tr.margin
        if closer and not was:  # an exit; if it is refused, trace on to the next one
            yield np.array(pts)
            exits += 1
            if exits >= _MAX_EXITS:
                yield NoCandidate(f"{_MAX_EXITS} exits along the contour, none acceptable")
                return
        r = math.hypot(x - lx, y - ly)
        if not away and r > 6.0 * step:
            away = True
        elif away and r < 2.5 * step:  # closed on itself: raise the level
            raises += 1
            if raises > _MAX_RAISES:
                yield NoCandidate(f"the contour closed at every level up to {c:.3g} without an exit")
                return
            c *= 1.5
            lx, ly, away = x, y, False
    yield NoCandidate(f"the contour found no exit within {tr.budget} steps")


# Route searches that found the unit or the goal walled in, per field (a field is immutable).
_WALLED: weakref.WeakKeyDictionary[
    ThreatField, list[tuple[tuple[float, float], GridGraph, np.ndarray, str]]
] = weakref.WeakKeyDictionary()


_WIDEST: weakref.WeakKeyDictionary[ThreatField, float] = weakref.WeakKeyDictionary()


def global_route(tr: Trap, routes: RouteCache | None = None) -> np.ndarray | NoCandidate:
    """``global_corners`` resampled at ``step``: the points the stepper follows."""
    corners = global_corners(tr, routes)
    return corners if isinstance(corners, NoCandidate) else polylines.resample(corners, tr.step)


def global_corners(tr: Trap, routes: RouteCache | None = None) -> np.ndarray | NoCandidate:
    """The whole way from the trap point to the goal as its corners, or why there is none.

    Dijkstra cost-to-go, cost ``1 + LAMBDA T``, on a local grid without the
    search cores (``cores.SEARCH_FRACTION``: the check's cores and a sliver,
    so a route between grid nodes never clips one), coarse to fine: the
    coarse ``route_cell`` first, and the fine one only when the coarse grid
    finds no route (a gap too narrow for it, or no way at all); then shortcut
    wherever a straight segment costs no more and stays out of them.
    ``global_route`` resamples it at ``step``; a committed run keeps only
    the corners (``EscapeRun.along``).

    The search comes from ``routes`` (default ``routes.ROUTES``): units with
    one goal under one field share it, and each walks its own way down it.
    """
    cache = ROUTES if routes is None else routes
    gx, gy = tr.goal
    for goal, known, walled, side in _WALLED.get(tr.field, ()):
        inside = bool(walled[known.cell_of(tr.x, tr.y)])
        if goal == tr.goal and inside == (side == "source"):  # the same walled-in component as before
            return NoCandidate(
                f"no route to the goal avoids the {_what(tr)}: the {'unit' if inside else 'goal'} is "
                f"walled in{_walls(tr, known, walled)} (local grid of {known.cell_m:.3g} m cells)"
            )
    widest = _WIDEST.get(tr.field)
    if widest is None:  # a field is immutable: its widest threat is found once
        widest = _WIDEST[tr.field] = max((t.spread() for t in tr.field.threats), default=0.0)
    spreads = [widest] if tr.field.threats else [tr.step]
    search = Cores.of(tr.field, SEARCH_FRACTION)
    s_min = tr.cores.min_spread_m if math.isfinite(tr.cores.min_spread_m) else tr.dist
    pad = max(0.3 * tr.dist, 3.0 * max(spreads))
    for _ in range(2):  # a trap close to the goal may need more room to go round: once, 3x the pad
        (x0, y0), (x1, y1) = (
            (min(tr.x, gx) - pad, min(tr.y, gy) - pad),
            (max(tr.x, gx) + pad, max(tr.y, gy) + pad),
        )
        x0, y0, x1, y1 = _round_zones(tr, x0, y0, x1, y1)
        if tr.bounds is not None:
            (bx0, by0), (bx1, by1) = tr.bounds
            x0, y0, x1, y1 = max(x0, bx0), max(y0, by0), min(x1, bx1), min(y1, by1)
        span = max(x1 - x0, y1 - y0)
        sight = finest_cell(tr.field.packed)
        coarse, fine = route_cell(span, s_min, False, sight), route_cell(span, s_min, True, sight)
        for h in (coarse, fine) if coarse > 1.01 * fine else (fine,):
            ask = Ask(
                tr.field,
                search,
                (tr.x, tr.y),
                tr.goal,
                LAMBDA,
                ((x0, y0), (x1, y1)),
                h,
                tr.bounds,
                tr.unit_key,
            )
            found = cache.find(ask)
            if len(found.polyline):
                break
        whole = tr.bounds is not None and ((x0, y0), (x1, y1)) == tr.bounds
        if len(found.polyline) or found.route.sealed or whole:
            break  # found, walled in, or the whole mission area already: more room cannot help
        pad *= 3.0
    if not len(found.polyline):
        route, grid = found.route, found.grid
        assert grid is not None  # no route: the whole grid was built (A* answers only when it finds one)
        if route.walled is not None:  # remembered for the next trap under this field
            _WALLED.setdefault(tr.field, []).append((tr.goal, grid, route.walled, route.walled_side))
        walls = _walls(tr, grid, route.walled) if route.walled is not None else ""
        return NoCandidate(
            f"no route to the goal avoids the {_what(tr)}"
            + (
                f": the {'unit' if route.walled_side == 'source' else 'goal'} is walled in{walls}"
                if walls
                else ""
            )
            + f" (local grid of {grid.cell_m:.3g} m cells)"
        )
    corners = np.asarray(found.polyline, dtype=np.float64)
    return wary_tie(ask, corners, tr.step, cache) if math.isfinite(sight) else corners


def _what(tr: Trap) -> str:
    return "threat cores and zones" if tr.field.zones else "threat cores"


def _round_zones(tr: Trap, x0: float, y0: float, x1: float, y1: float) -> tuple[float, float, float, float]:
    """The search box grown to hold every keep-out zone it meets, and room to go round (twice: zones in a chain)."""
    zones = tr.field.zones
    if not zones:
        return x0, y0, x1, y1
    room = 4.0 * tr.step
    for _ in range(2):
        b = zones.boxes
        meet = (b[:, 0] <= x1) & (b[:, 2] >= x0) & (b[:, 1] <= y1) & (b[:, 3] >= y0)
        if not meet.any():
            break
        x0 = min(x0, float(b[meet, 0].min()) - room)
        y0 = min(y0, float(b[meet, 1].min()) - room)
        x1 = max(x1, float(b[meet, 2].max()) + room)
        y1 = max(y1, float(b[meet, 3].max()) + room)
    return x0, y0, x1, y1


def _walls(tr: Trap, grid: GridGraph, walled: np.ndarray) -> str:
    """`` by zone A, the core of threat B``: what the blocked nodes round a walled-in component lie in."""
    m = walled.reshape(grid.nx, grid.ny)
    grown = m.copy()
    grown[1:] |= m[:-1]
    grown[:-1] |= m[1:]
    grown[:, 1:] |= m[:, :-1]
    grown[:, :-1] |= m[:, 1:]
    rim = (grown & ~m).ravel() & ~grid.open
    pts = grid.nodes[rim]
    if len(pts) > 4000:
        pts = pts[:: math.ceil(len(pts) / 4000)]
    names: list[str] = []
    if tr.field.zones:
        sd, ids = tr.field.zones.nearest_many(pts)
        names += sorted({f"zone {z}" for d, z in zip(sd.tolist(), ids) if z and d <= 2.0 * grid.cell_m})
    if len(tr.cores.packed) and len(pts):
        ratio, idx = tr.cores.ratio(pts)
        near = ratio >= 0.5 * SEARCH_FRACTION
        names += sorted({f"the core of threat {tr.cores.ids[i]}" for i in idx[near].tolist() if i >= 0})
    return (
        (" by " + ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else ""))
        if names
        else ""
    )


def _global(tr: Trap) -> Iterator[Candidate]:
    poly = global_route(tr)
    if isinstance(poly, NoCandidate):
        yield poly
        return
    for frac in (0.25, 0.5, 0.75):
        yield poly[: max(2, int(frac * len(poly)))]
    yield poly


@dataclass(frozen=True, slots=True)
class Strategy:
    """One way out of a trap.

    Attributes:
        name: the ``escape`` value that selects it alone.
        tier: ``auto`` asks a tier only when every lower one found nothing acceptable.
        propose: candidate escape paths for a trap, cheapest first, or a ``NoCandidate``.
        summary: one line for help text.
    """

    name: str
    tier: int
    propose: Callable[[Trap], Iterator[Candidate]]
    summary: str


_REGISTRY = (
    Strategy("delta", 0, _delta, "descent with the goal weight raised x4, x16, x64"),
    Strategy("random", 0, _random, "a seeded random heading held for 3 trap windows"),
    Strategy("waypoint", 0, _waypoint, "descent towards a point beside the threat cluster"),
    Strategy("contour", 0, _contour, "follow the iso-threat line round the trap"),
    Strategy("global", 1, _global, "cheapest core-free route on a local grid"),
)

STRATEGIES: MappingProxyType[str, Strategy] = MappingProxyType(
    {s.name: s for s in sorted(_REGISTRY, key=lambda s: s.tier)}
)
"""Every strategy by name, in ``auto``'s order (by tier, then as registered)."""

AUTO_ORDER: tuple[str, ...] = tuple(STRATEGIES)
