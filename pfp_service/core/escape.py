"""Trap escape for one unit: choose a way out, judge it, then steer along it.

The stepper hands a trap to its ``Escaper`` only after plain descent has
given its trapped verdict, so descent itself pays nothing for this module.

Choosing.  ``escape`` names one strategy (``escape_strategies.STRATEGIES``)
or ``auto``, which escalates tier by tier: it asks each strategy of the
cheapest tier (``delta, random, waypoint, contour``) for its first acceptable
candidate and commits to the one of least estimated
``J = length + LAMBDA * exposure`` to the goal (escape path, simulated descent
after it, straight remainder).  It pays for the next tier (``global``) when
none of them has one, or when the best costs more than ``1 + AUTO_MARGIN``
times the straight line to the goal; a dearer candidate wins only when it is
cheaper by more than ``AUTO_MARGIN`` (5 %).  A single named strategy commits
to its own first acceptable candidate.  A goal inside a threat core is
refused at once, with a reason naming the threat.  Every candidate is *judged* before
the unit moves:

1. it may not enter a threat core (``cores``) nor leave the mission bounds;
2. simulated plain descent from its exit may not enter a core either, and
   must reach the goal or end clearly closer to it than the trap was
   (``margin = max(4 step, 5 % of the trap distance)``).

This is what makes ``auto`` refuse to raise delta through a symmetric block:
that candidate enters the block's core, so the next strategy is asked.  A
strategy already used at the same trap (within ``max(10 step, margin)``) is
not asked again there.  When nothing passes, the verdict is ``trapped`` with
every strategy's reason; at most ``MAX_TRAPS`` escapes are made per goal.

Steering (``core.route``).  The committed path is followed by aiming two
points ahead of the nearest path point (a live unit's pursuit point lies
farther, ``core.tracking``), found from the reported position, so a unit
that drifts a little still follows it.  The escape ends at the exit (or is abandoned
after ``2 * len(path) + 20`` advisories) and plain descent resumes, except
that a path ending within ``HANDOFF_STEPS`` steps of the goal is followed on
to the goal itself: near the goal a threat's gradient can be a hundred times
the goal's pull, and descent there would drift off a route that had arrived.

Randomness comes from ``numpy.random.default_rng([seed, unit_key, trap])``:
the same unit, seed and trap always make the same choice, live or preview.

Foreseen traps.  Under ``auto`` the stepper also simulates its own descent
when the goal is set and after each world change (``foresight``).  When that
simulation is trapped (or leaves the bounds), ``foresee`` commits at once to
the whole ``global`` route, judged like any candidate: a way round chosen
before the unit walks in, not after.  That route is the Dijkstra optimum of
``length + LAMBDA * exposure``, shortcut, so it lies near the
length/exposure Pareto front; the cheap strategies stay for traps that were
not foreseen (drift, or threats that appear later).  When the simulation
arrives instead, ``cheaper_route`` compares its ``J`` with the route's and
commits to the route only when it is cheaper by more than ``AUTO_MARGIN``
(descent down a channel between threats arrives, at a high price).  A unit
that starts inside a core first leaves it by the shortest straight way out
(``leave_core``; its escape is logged as ``leave core <id>``, or ``leave zone <id>``
for a keep-out zone, left past its nearest edge).
"""

from __future__ import annotations

import math

import numpy as np

from pfp_service.core import cull
from pfp_service.core.cores import ZONE_PREFIX, Cores
from pfp_service.core.escape_strategies import (
    AUTO_ORDER,
    STRATEGIES,
    Bounds,
    NoCandidate,
    Trap,
    global_corners,
    rollout,
)
from pfp_service.core.foresight import coarser, progress_floor
from pfp_service.core.metrics import LAMBDA, path_cost
from pfp_service.core.options import ESCAPE_STRATEGIES
from pfp_service.core.params import Resolved
from pfp_service.core.polylines import polyline_clear, resample
from pfp_service.core.route import NO_POINTS, EscapeRun, legs, path_length
from pfp_service.core.threat import ThreatField
from pfp_service.core.tracking import Route

__all__ = ["AUTO_MARGIN", "AUTO_ORDER", "HANDOFF_STEPS", "MAX_TRAPS", "TRAP_BUDGET", "Escaper"]

# The ``escape`` choices users are offered (options, read without compiling the core) must be the
# strategies there are, in auto's order: a strategy registered without its name, or the reverse, fails here.
if AUTO_ORDER != ESCAPE_STRATEGIES:
    raise ImportError(
        f"escape_strategies registers {AUTO_ORDER}; options.ESCAPE_STRATEGIES names {ESCAPE_STRATEGIES}"
    )

MAX_TRAPS = 12
TRAP_BUDGET = 8000  # most steps a strategy walks from a trap
RUN_MAX_POINTS = 10_000_000  # a committed run walked at the unit's step, unless it would have more points
AUTO_MARGIN = 0.05  # "clearly cheaper": a dearer way is taken only when it saves more than 5 % of J
HANDOFF_STEPS = 4.0  # an escape ending this many steps from the goal steers on to it


def route_cost(path: np.ndarray, field: ThreatField, lam: float = LAMBDA) -> float:
    """``metrics.path_cost`` of a way to rank, each level summed over its own cell of the field's index.

    Simpson on every segment, as ``path_cost``; among many threats each point
    sums only the threats its cell of ``cull.index_of(field)`` lists (off by
    at most the index's ``level_bound``), and each vertex is evaluated once.
    """
    index = cull.index_of(field)
    pts = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    if index is None or len(pts) < 2:
        return path_cost(pts, field, lam)
    mid = 0.5 * (pts[:-1] + pts[1:])
    lv = cull.cell_level(index, np.concatenate([pts, mid]))
    vert, half = lv[: len(pts)], lv[len(pts) :]
    seglen = np.hypot(*np.diff(pts, axis=0).T)
    exposure = float(np.sum(seglen * (vert[:-1] + 4.0 * half + vert[1:])) / 6.0)
    return float(seglen.sum()) + lam * exposure


def _leaving(run: EscapeRun) -> EscapeRun:
    run.route = Route.LEAVE
    return run


class _Site:
    __slots__ = ("tried", "x", "y")

    def __init__(self, x: float, y: float) -> None:
        self.x, self.y = x, y
        self.tried: set[str] = set()


class Escaper:
    """The escape state of one unit for one goal: its traps and what was tried at each.

    Args:
        params: the stepper's resolved parameters (``escape`` must not be ``none``).
        goal, goal_gain: the stepper's goal and ``delta / ||goal - x0||^2``.
        bounds: the mission bounds, if any.
        unit_key: distinguishes units for the seeded random strategy.
    """

    def __init__(
        self,
        params: Resolved,
        goal: tuple[float, float],
        goal_gain: float,
        bounds: Bounds | None,
        unit_key: int,
    ) -> None:
        self.params = params
        self.goal = goal
        self.goal_gain = goal_gain
        self.bounds = bounds
        self.unit_key = unit_key
        self.traps = 0
        self.escape_steps = 0
        self.log: list[str] = []
        self._sites: list[_Site] = []

    def __deepcopy__(self, memo: dict[int, object]) -> Escaper:
        """A detached copy (deliberation, previews): the parameters and goal shared, the history copied."""
        new = Escaper.__new__(Escaper)
        new.__dict__.update(self.__dict__)
        new.log = list(self.log)
        new._sites = []
        for site in self._sites:
            twin = _Site(site.x, site.y)
            twin.tried = set(site.tried)
            new._sites.append(twin)
        return new

    def forget_sites(self) -> None:
        """The world changed: what failed at a trap before may work now."""
        self._sites.clear()

    def begin(self, field: ThreatField, x: float, y: float, reason: str) -> tuple[EscapeRun | None, str]:
        """Pick an escape from a trap at ``(x, y)``.

        Returns:
            ``(run, "")`` with the committed escape, or ``(None, why)`` when no
            candidate passes; ``why`` starts with the trap ``reason``.
        """
        self.traps += 1
        if self.traps > MAX_TRAPS:
            return None, f"{reason}; gave up after {MAX_TRAPS} escapes"
        trap = self._trap(field, x, y)
        inside = trap.cores.core_at(*self.goal)
        if inside:
            return None, f"{reason}; the goal lies in {Cores.region(inside)}, which no escape enters"
        site = self._site(x, y, max(10.0 * self.params.step, trap.margin))
        order = AUTO_ORDER if self.params.escape == "auto" else (self.params.escape,)
        refusals: list[str] = []
        best: tuple[float, str, np.ndarray] | None = None
        for name in order:
            tier = STRATEGIES[name].tier
            dearer = best is not None and tier > STRATEGIES[best[1]].tier
            if best is not None and dearer and best[0] <= (1.0 + AUTO_MARGIN) * trap.dist:
                break  # nothing can beat the straight line clearly: no need for a dearer tier
            if name in site.tried:
                refusals.append(f"{name}: already tried at this trap")
                continue
            found = self._first_pass(trap, name, refusals)
            if found is None:
                continue
            if best is None or found[0] * (1.0 + (AUTO_MARGIN if dearer else 0.0)) < best[0]:
                best = (found[0], name, found[1])
        if best is None:
            return None, f"{reason}; no escape found: " + "; ".join(refusals)
        _, name, path = best
        site.tried.add(name)
        self.log.append(name)
        return self._run(name, path, trap), ""

    def foresee(self, field: ThreatField, x: float, y: float, ahead: str) -> tuple[EscapeRun | None, str]:
        """Plain descent from ``(x, y)`` is foreseen to end ``ahead`` (``foresight``): go round now.

        Rather than walk into the trap and back out, commit to the whole
        ``global`` route to the goal, judged like any candidate.

        Returns:
            ``(run, "")``, or ``(None, why)`` when there is no acceptable route;
            the stepper then descends and meets the trap as usual.
        """
        self.traps += 1
        tr = self._trap(field, x, y)
        inside = tr.cores.core_at(*self.goal)
        if inside:
            return None, f"{ahead} foreseen; the goal lies in {Cores.region(inside)}"
        corners = global_corners(tr)
        if isinstance(corners, NoCandidate):
            return None, f"{ahead} foreseen; {corners.reason}"
        poly = resample(corners, tr.step)
        verdict, _ = self._judge(tr, poly)
        if verdict:
            return None, f"{ahead} foreseen; global: {verdict}"
        self.log.append("global")
        return self._run(f"global ({ahead} foreseen)", poly, tr, corners, Route.AROUND_TRAP), ""

    def cheaper_route(self, field: ThreatField, x: float, y: float, foreseen_cost: float) -> EscapeRun | None:
        """Plain descent from ``(x, y)`` is foreseen to arrive at ``J = foreseen_cost``: is going round clearly cheaper?

        The ``global`` route is searched only when the foreseen ``J`` exceeds
        the straight-line distance by more than ``AUTO_MARGIN`` (no route can
        beat it by more otherwise), and committed to only when its own ``J``
        is lower by more than ``AUTO_MARGIN``, and it passes the judge.
        """
        dist = math.hypot(self.goal[0] - x, self.goal[1] - y)
        if not foreseen_cost > (1.0 + AUTO_MARGIN) * dist:
            return None
        tr = self._trap(field, x, y)
        if tr.cores.core_at(*self.goal):
            return None
        corners = global_corners(tr)
        if isinstance(corners, NoCandidate):
            return None
        if path_length(corners) * (1.0 + AUTO_MARGIN) >= foreseen_cost:
            return None  # its J is at least its length (exposure is never negative): no need to price it
        poly = resample(corners, tr.step)
        if self._judge(tr, poly)[0] or route_cost(poly, field) * (1.0 + AUTO_MARGIN) >= foreseen_cost:
            return None
        self.log.append("global")
        return self._run("global (cheaper than descent)", poly, tr, corners, Route.LOWER_EXPOSURE)

    def leave_core(self, field: ThreatField, x: float, y: float) -> EscapeRun | None:
        """``None`` unless ``(x, y)`` lies in a threat core; then the shortest straight way out of every core."""
        cores = Cores.of(field)
        inside = cores.core_at(x, y)
        if not inside:
            return None
        p = self.params
        if inside.startswith(ZONE_PREFIX):  # a zone's shortest way out is exact: past its nearest edge
            zone = inside[len(ZONE_PREFIX) :]
            end = cores.zones.way_out(x, y, p.step)
            if end is None:
                return None
            self.log.append(f"leave zone {zone}")
            return _leaving(EscapeRun.along(f"leave zone {zone}", np.array([(x, y), end]), p.step))
        spacing = min(p.step, cores.min_spread_m / 4.0)
        reach = 6.0 * max(t.spread() for t in field.threats)
        n = min(2000, math.ceil(reach / spacing))
        angles = np.linspace(0.0, 2.0 * math.pi, 72, endpoint=False)
        d = np.arange(1, n + 1) * (reach / n)
        rays = np.stack([x + np.sin(angles)[:, None] * d, y + np.cos(angles)[:, None] * d], axis=-1)
        out = cores.first_clear(rays)  # per ray, its first point in no core and no zone (n: none)
        k = int(np.argmin(out))
        if out[k] >= n:
            return None  # no straight way out within reach: descend as usual
        r = d[min(out[k], n - 1)] + p.step  # one step clear of the core's edge
        end = (x + math.sin(angles[k]) * r, y + math.cos(angles[k]) * r)
        self.log.append(f"leave core {inside}")
        return _leaving(
            EscapeRun.along(f"leave the core of threat {inside}", np.array([(x, y), end]), p.step)
        )

    def _run(
        self,
        name: str,
        path: np.ndarray,
        tr: Trap,
        corners: np.ndarray | None = None,
        route: Route = Route.ESCAPE,
    ) -> EscapeRun:
        """The run for a committed path; one ending near the goal goes on to it (``EscapeRun.to_goal``).

        ``corners``: ``path`` is ``resample(corners, step)``, and the run keeps only its legs.
        ``route``: what the run is, for the direction.
        """
        run = self._made(name, path, tr, corners)
        run.route = route
        return run

    def _made(self, name: str, path: np.ndarray, tr: Trap, corners: np.ndarray | None) -> EscapeRun:
        gx, gy = self.goal
        ex, ey = path[-1]
        near = math.hypot(gx - ex, gy - ey) <= HANDOFF_STEPS * tr.step
        to_goal = bool(near and not tr.cores.first_hit(np.array([(ex, ey), (gx, gy)])))
        tail = np.array([(ex, ey), (gx, gy)]) if to_goal and (ex, ey) != (gx, gy) else None
        step = self.params.step  # the unit's own: a trap searched coarser (``_trap``) is walked at it ...
        if path_length(path if corners is None else corners) > RUN_MAX_POINTS * step:
            step = tr.step  # ... unless that would make a run of absurdly many points (a denormal step)
        if corners is None and tr.step == step:
            if tail is not None:
                path = np.concatenate([path, resample(tail, step)[1:]])
            return EscapeRun(name, path, step, to_goal)
        segs = legs(path if corners is None else corners, step)
        if tail is not None:
            more = legs(tail, step)
            more[:, 4] += segs[-1, 4]
            segs = np.concatenate([segs, more])
        return EscapeRun(name, NO_POINTS, step, to_goal, segs=segs)

    def _trap(self, field: ThreatField, x: float, y: float) -> Trap:
        """The trap at ``(x, y)`` as the strategies search it.

        Their walks are counted in steps (at most ``TRAP_BUDGET``): a step so
        fine that six times the distance to the goal would not fit is searched
        at the coarser step that fits, as the look-ahead is
        (``foresight.resolution``), so an escape found at the default step is
        found at a hundredth of it too; the committed run is walked at the
        unit's own step (``_made``).
        """
        p = self.params
        dist = math.hypot(self.goal[0] - x, self.goal[1] - y)
        if math.isfinite(dist) and 6.0 * dist > TRAP_BUDGET * p.step:
            p = coarser(p, max(6.0 * dist / TRAP_BUDGET, progress_floor(p)))
        return Trap(
            field=field,
            cores=Cores.of(field),
            x=x,
            y=y,
            goal=self.goal,
            delta=p.delta,
            gain=self.goal_gain,
            step=p.step,
            tolerance=p.tolerance,
            trap_window=p.trap_window,
            dist=dist,
            margin=max(4.0 * p.step, 0.05 * dist),
            budget=int(
                min(TRAP_BUDGET, max(10 * p.trap_window, math.ceil(min(6.0 * dist / p.step, TRAP_BUDGET))))
            ),
            bounds=self.bounds,
            rng=np.random.default_rng([p.seed & 0xFFFFFFFF, self.unit_key & 0xFFFFFFFF, self.traps]),
            unit_key=self.unit_key,
        )

    def _first_pass(self, tr: Trap, name: str, refusals: list[str]) -> tuple[float, np.ndarray] | None:
        """The first candidate of strategy ``name`` that passes, with its estimated cost to the goal."""
        why, n = "", 0
        for cand in STRATEGIES[name].propose(tr):
            if isinstance(cand, NoCandidate):
                why = why or cand.reason
                break
            n += 1
            verdict, after = self._judge(tr, cand)
            if not verdict:
                return self._cost(tr, cand, after), cand
            why = why or verdict
        refusals.append(f"{name}: {why or 'no candidate'}" + (f" ({n} candidates refused)" if n > 1 else ""))
        return None

    @staticmethod
    def _cost(tr: Trap, poly: np.ndarray, after: np.ndarray) -> float:
        """``J`` of the escape, the descent after it, and the straight remainder to the goal."""
        pts = np.concatenate([poly, after[1:]])
        rest = math.hypot(tr.goal[0] - pts[-1, 0], tr.goal[1] - pts[-1, 1])
        return route_cost(pts, tr.field) + rest

    def _site(self, x: float, y: float, radius: float) -> _Site:
        for s in self._sites:
            if math.hypot(s.x - x, s.y - y) <= radius:
                return s
        s = _Site(x, y)
        self._sites.append(s)
        return s

    def _judge(self, tr: Trap, poly: np.ndarray) -> tuple[str, np.ndarray]:
        """``("", descent after it)`` if the candidate is acceptable, else ``(why not, ...)``."""
        none = poly[-1:]
        if len(poly) < 2:
            return "goes nowhere", none
        if self.bounds is not None:
            (x0, y0), (x1, y1) = self.bounds
            if np.any((poly[:, 0] < x0) | (poly[:, 0] > x1) | (poly[:, 1] < y0) | (poly[:, 1] > y1)):
                return "leaves the mission bounds", none
        hit = "" if polyline_clear(tr.cores, poly) else tr.cores.first_hit(poly)
        if hit:
            return f"passes through {Cores.region(hit)}", none
        end = (float(poly[-1, 0]), float(poly[-1, 1]))
        n = int(min(20000, math.ceil(3.0 * tr.dist / tr.step) + 4 * tr.trap_window))
        after = rollout(tr.field, end, tr.goal, tr.gain, tr.step, tr.tolerance, n)
        hit = "" if polyline_clear(tr.cores, after) else tr.cores.first_hit(after)
        if hit:
            return f"descent after it passes through {Cores.region(hit)}", after
        d_end = math.hypot(tr.goal[0] - after[-1, 0], tr.goal[1] - after[-1, 1])
        if d_end > tr.tolerance and d_end > tr.dist - tr.margin:
            return "descent after it ends no closer to the goal", after
        return "", after
