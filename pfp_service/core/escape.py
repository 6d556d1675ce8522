"""Trap escape for one unit: choose a way out, judge it, then steer along it.

The stepper hands a trap to its ``Escaper`` only after plain descent has
given its trapped verdict, so descent itself pays nothing for this module.

Choosing.  ``escape`` names one strategy (``escape_strategies.STRATEGIES``)
or ``auto``, which escalates tier by tier: it asks each strategy of the
cheapest tier (``delta, random, waypoint, contour``) for its first acceptable
candidate and commits to the one of least estimated
``J = length + LAMBDA * exposure`` to the goal (escape path, simulated descent
after it, straight remainder); only when none of them has one does it pay for
the next tier (``global``).  A single named strategy commits to its own first
acceptable candidate.  Every candidate is *judged* before
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

Steering.  The committed path is followed by aiming two points ahead of the
nearest path point, found from the reported position, so a unit that drifts
a little still follows it.  The escape ends at the exit (or is abandoned
after ``2 * len(path) + 20`` advisories) and plain descent resumes.

Randomness comes from ``numpy.random.default_rng([seed, unit_key, trap])``:
the same unit, seed and trap always make the same choice, live or preview.

Foreseen traps.  Under ``auto`` the stepper also simulates its own descent
when the goal is set and after each world change (``foresight``).  When that
simulation is trapped (or leaves the bounds), ``foresee`` commits at once to
the whole ``global`` route, judged like any candidate: a way round chosen
before the unit walks in, not after.  That route is the Dijkstra optimum of
``length + LAMBDA * exposure``, shortcut, so it lies near the
length/exposure Pareto front; the cheap strategies stay for traps that were
not foreseen (drift, or threats that appear later).
"""

from __future__ import annotations

import math

import numpy as np

from pfp_service.core.cores import Cores
from pfp_service.core.escape_strategies import (
    AUTO_ORDER,
    STRATEGIES,
    Bounds,
    NoCandidate,
    Trap,
    global_route,
    rollout,
)
from pfp_service.core.metrics import path_cost
from pfp_service.core.params import Resolved
from pfp_service.core.threat import ThreatField

__all__ = ["AUTO_ORDER", "MAX_TRAPS", "EscapeRun", "Escaper"]

MAX_TRAPS = 12


class EscapeRun:
    """A committed escape: the path to steer along and how far along the unit is."""

    __slots__ = ("advisories", "cursor", "limit", "name", "path", "step")

    def __init__(self, name: str, path: np.ndarray, step: float) -> None:
        self.name = name
        self.path: list[tuple[float, float]] = [(float(a), float(b)) for a, b in path]
        self.cursor = 0
        self.advisories = 0
        self.limit = 2 * len(self.path) + 20
        self.step = step

    def direction(self, x: float, y: float) -> tuple[float, float] | None:
        """Unit heading towards the path ahead, or ``None`` once at the exit (or abandoned)."""
        self.advisories += 1
        if self.advisories > self.limit:
            return None
        p = self.path
        i = self.cursor
        window = p[i : i + 16]
        i += min(range(len(window)), key=lambda k: (window[k][0] - x) ** 2 + (window[k][1] - y) ** 2)
        self.cursor = i
        ex, ey = p[-1]
        if i >= len(p) - 2 and math.hypot(ex - x, ey - y) <= self.step:
            return None
        tx, ty = p[min(i + 2, len(p) - 1)]
        dx, dy = tx - x, ty - y
        n = math.hypot(dx, dy)
        if n <= 1e-9 * self.step:
            return None
        return dx / n, dy / n


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
        site = self._site(x, y, max(10.0 * self.params.step, trap.margin))
        order = AUTO_ORDER if self.params.escape == "auto" else (self.params.escape,)
        refusals: list[str] = []
        best: tuple[float, str, np.ndarray] | None = None
        for name in order:
            if best is not None and STRATEGIES[name].tier > STRATEGIES[best[1]].tier:
                break  # a dearer tier only when every cheaper one failed
            if name in site.tried:
                refusals.append(f"{name}: already tried at this trap")
                continue
            found = self._first_pass(trap, name, refusals)
            if found is not None and (best is None or found[0] < best[0]):
                best = (found[0], name, found[1])
        if best is None:
            return None, f"{reason}; no escape found: " + "; ".join(refusals)
        _, name, path = best
        site.tried.add(name)
        self.log.append(name)
        return EscapeRun(name, path, self.params.step), ""

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
        poly = global_route(tr)
        if isinstance(poly, NoCandidate):
            return None, f"{ahead} foreseen; {poly.reason}"
        verdict, _ = self._judge(tr, poly)
        if verdict:
            return None, f"{ahead} foreseen; global: {verdict}"
        self.log.append("global")
        return EscapeRun(f"global ({ahead} foreseen)", poly, self.params.step), ""

    def _trap(self, field: ThreatField, x: float, y: float) -> Trap:
        p = self.params
        dist = math.hypot(self.goal[0] - x, self.goal[1] - y)
        return Trap(
            field=field,
            cores=Cores(field),
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
            budget=int(min(8000, max(10 * p.trap_window, math.ceil(6.0 * dist / p.step)))),
            bounds=self.bounds,
            rng=np.random.default_rng([p.seed & 0xFFFFFFFF, self.unit_key & 0xFFFFFFFF, self.traps]),
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
        return path_cost(pts, tr.field) + rest

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
        hit = tr.cores.first_hit(poly)
        if hit:
            return f"passes through the core of threat {hit}", none
        end = (float(poly[-1, 0]), float(poly[-1, 1]))
        n = int(min(20000, math.ceil(3.0 * tr.dist / tr.step) + 4 * tr.trap_window))
        after = rollout(tr.field, end, tr.goal, tr.gain, tr.step, tr.tolerance, n)
        hit = tr.cores.first_hit(after)
        if hit:
            return f"descent after it passes through the core of threat {hit}", after
        d_end = math.hypot(tr.goal[0] - after[-1, 0], tr.goal[1] - after[-1, 1])
        if d_end > tr.tolerance and d_end > tr.dist - tr.margin:
            return "descent after it ends no closer to the goal", after
        return "", after
