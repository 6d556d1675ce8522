"""The per-unit stepper: given where a unit is, say which way it should go next.

One stepper serves two drivers.  ``plan()`` moves a simulated unit along the
directions it returns (a preview); the live daemon feeds it the positions the
unit reports.  Its state is the unit's goal, its mode and a short recent track,
which is what trap detection needs.  It never reads a clock and never moves the
unit itself.

Trap detection (plain descent has no memory, so this is the only guard):

* *stall*: over the last ``trap_window`` advisories the unit moved less than
  ``0.2 * trap_window * step`` net, i.e. it is oscillating about a point;
* *no progress*: the best distance to goal has not improved by a tolerance in
  ``progress_window`` advisories (a slow creep into a basin or an orbit).

Either one ends plain descent with ``trapped`` and the reason, rather than
running on silently to ``max_iter``.
"""

from __future__ import annotations

import math
from collections import deque
from enum import Enum
from typing import NamedTuple

import numpy as np

from pfp_service.core import kernels
from pfp_service.core.params import Resolved
from pfp_service.core.threat import ThreatField

__all__ = ["Advice", "Bounds", "StepStatus", "Stepper", "advise_many"]

Bounds = tuple[tuple[float, float], tuple[float, float]]


class StepStatus(str, Enum):
    """What the stepper says about the unit at this position."""

    EN_ROUTE = "en_route"
    ESCAPING = "escaping"
    ARRIVED = "arrived"
    TRAPPED = "trapped"
    OUT_OF_BOUNDS = "out_of_bounds"
    INVALID = "invalid"

    @property
    def terminal(self) -> bool:
        return self not in (StepStatus.EN_ROUTE, StepStatus.ESCAPING)


class Advice(NamedTuple):
    """One answer of the stepper.

    ``dx, dy`` is a unit vector (``0, 0`` when the status is terminal);
    ``level`` is the weighted threat level at the position; ``distance`` is the
    distance to the goal in metres.
    """

    status: StepStatus
    dx: float
    dy: float
    level: float
    distance: float
    reason: str = ""


class Stepper:
    """Steepest descent on ``f = sum_j w_j t_j + delta ||goal - x||^2 / ||goal - x0||^2``.

    Args:
        origin: ``x0``, where the unit was when the goal was assigned.
        goal: the target position.
        params: resolved planner parameters (``core.params.resolve``).
        bounds: optional ``((xmin, ymin), (xmax, ymax))``; leaving them ends the run.
    """

    __slots__ = (
        "goal",
        "origin",
        "params",
        "bounds",
        "goal_gain",
        "advisories",
        "_recent",
        "_best",
        "_since_best",
        "_terminal",
    )

    def __init__(
        self,
        origin: tuple[float, float],
        goal: tuple[float, float],
        params: Resolved,
        bounds: Bounds | None = None,
    ) -> None:
        self.goal = (float(goal[0]), float(goal[1]))
        self.origin = (float(origin[0]), float(origin[1]))
        self.params = params
        self.bounds = bounds
        d0sq = (self.goal[0] - self.origin[0]) ** 2 + (self.goal[1] - self.origin[1]) ** 2
        self.goal_gain = params.delta / d0sq if d0sq > 0 else 0.0
        self.advisories = 0
        self._recent: deque[tuple[float, float]] = deque(maxlen=params.trap_window)
        self._best = math.inf
        self._since_best = 0
        self._terminal: Advice | None = None

    def world_changed(self) -> None:
        """Threats appeared, moved or vanished: judge progress afresh from here."""
        self._recent.clear()
        self._best = math.inf
        self._since_best = 0
        if self._terminal is not None and self._terminal.status is StepStatus.TRAPPED:
            self._terminal = None

    def advise(self, field: ThreatField, x: float, y: float) -> Advice:
        """The next direction for a unit at ``(x, y)`` under ``field``."""
        early = self.check(x, y)
        if early is not None:
            return early
        fx, fy, level, norm = kernels.point_descent(
            field.packed, x, y, self.goal[0], self.goal[1], self.goal_gain
        )
        return self.follow(x, y, fx, fy, level, norm)

    def check(self, x: float, y: float) -> Advice | None:
        """The part of ``advise`` that needs no field: arrival, bounds, a standing verdict."""
        gx, gy = self.goal
        dist = math.hypot(gx - x, gy - y)
        if not (math.isfinite(x) and math.isfinite(y)):
            return self._end(StepStatus.INVALID, 0.0, dist, "position is not finite")
        if dist <= self.params.tolerance:
            return self._end(StepStatus.ARRIVED, 0.0, dist, "within tolerance")
        if self.bounds is not None:
            (x0, y0), (x1, y1) = self.bounds
            if not (x0 <= x <= x1 and y0 <= y <= y1):
                return self._end(StepStatus.OUT_OF_BOUNDS, 0.0, dist, "left the mission bounds")
        return self._terminal

    def follow(self, x: float, y: float, fx: float, fy: float, level: float, norm: float) -> Advice:
        """The rest of ``advise``, given the potential's gradient at ``(x, y)``.

        ``advise_many`` computes the gradients of many units in one kernel call
        and then calls this per unit.
        """
        dist = math.hypot(self.goal[0] - x, self.goal[1] - y)
        if not math.isfinite(norm):
            return self._end(StepStatus.INVALID, level, dist, "gradient is not finite")
        if norm == 0.0:
            return self._end(StepStatus.TRAPPED, level, dist, "gradient vanishes (stationary point)")
        self.advisories += 1
        trapped = self._watch(x, y, dist)
        if trapped:
            return self._end(StepStatus.TRAPPED, level, dist, trapped)
        return Advice(StepStatus.EN_ROUTE, -fx / norm, -fy / norm, level, dist)

    # -- internals ----------------------------------------------------------
    def _watch(self, x: float, y: float, dist: float) -> str:
        p = self.params
        if dist < self._best - p.tolerance:
            self._best = dist
            self._since_best = 0
        else:
            self._since_best += 1
            if self._since_best >= p.progress_window:
                return f"no progress toward the goal in {p.progress_window} steps"
        recent = self._recent
        if len(recent) == p.trap_window:
            ox, oy = recent[0]
            if math.hypot(x - ox, y - oy) < 0.2 * p.trap_window * p.step:
                return f"oscillating: moved under {0.2 * p.trap_window:g} steps net in {p.trap_window}"
        recent.append((x, y))
        return ""

    def _end(self, status: StepStatus, level: float, dist: float, reason: str) -> Advice:
        advice = Advice(status, 0.0, 0.0, level, dist, reason)
        if status is StepStatus.TRAPPED:
            self._terminal = advice
        return advice


def advise_many(steppers: list[Stepper], field: ThreatField, positions: np.ndarray) -> list[Advice]:
    """``advise`` for many units under one field, with one vectorised kernel call.

    Args:
        steppers: one stepper per unit.
        field: the threats in force.
        positions: ``(N, 2)`` reported positions, row i for ``steppers[i]``.

    Returns:
        One ``Advice`` per stepper, in order; identical to calling ``advise`` one by one.
    """
    pts = np.ascontiguousarray(positions, dtype=np.float64).reshape(-1, 2)
    n = len(steppers)
    goals = np.empty((n, 2))
    gains = np.empty(n)
    for i, s in enumerate(steppers):
        goals[i] = s.goal
        gains[i] = s.goal_gain
    out = np.empty((n, 4))
    kernels.batch_descent(field.packed, pts, goals, gains, out)
    rows = out.tolist()
    coords = pts.tolist()
    result = []
    for s, (x, y), (fx, fy, level, norm) in zip(steppers, coords, rows):
        early = s.check(x, y)
        result.append(early if early is not None else s.follow(x, y, fx, fy, level, norm))
    return result
