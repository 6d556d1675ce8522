"""Looking ahead: simulate a unit's own plain descent, with the stepper's trap rules, before it moves.

Plain descent cannot see a trap until it is inside it: by then the walk in is
spent, and so is the walk back out.  Under ``escape: auto`` the stepper
therefore runs this simulation once when its goal is set and once after each
world change (never per advisory): plain descent from the unit's position,
exactly as ``Stepper.follow`` would advise it for a unit that moves ``step``
each time, with the same arrival, bounds, stall and no-progress rules.  If
the simulation ends ``trapped`` or out of bounds, the stepper commits to a way
round before walking in (``escape.Escaper.foresee``).

It is a prediction, not a promise: a live unit drifts from its advice, and a
trap the simulation missed is still caught, and escaped, when it happens.
It costs one compiled loop, about 0.1 ms for a few hundred steps, and never
more than ``FORESIGHT_MAX_STEPS`` steps (a few ms): the simulation runs on the
planning thread that serves every unit, and a goal given with a tiny explicit
step could otherwise ask for billions.  A simulation cut short ends
``runs_on``, which foresees no trap: the unit descends as under ``escape: none``
and a trap is still caught when it happens.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import NamedTuple

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.params import Resolved
from pfp_service.core.threat import ThreatField

__all__ = ["FORESIGHT_MAX_STEPS", "Foresight", "Outcome", "simulate"]

FORESIGHT_MAX_STEPS = 20_000

Bounds = tuple[tuple[float, float], tuple[float, float]]

_ARRIVES, _TRAPPED, _LEAVES, _STOPS, _RUNS_ON = range(5)


class Outcome(StrEnum):
    """How simulated plain descent ends."""

    ARRIVES = "arrives"
    TRAPPED = "trapped"
    LEAVES_BOUNDS = "leaves_bounds"
    STOPS = "stops"  # the position or gradient is not finite
    RUNS_ON = "runs_on"  # still going after the step budget

    @property
    def fails(self) -> bool:
        """A way round is worth planning now."""
        return self in (Outcome.TRAPPED, Outcome.LEAVES_BOUNDS)


_OUTCOMES = (Outcome.ARRIVES, Outcome.TRAPPED, Outcome.LEAVES_BOUNDS, Outcome.STOPS, Outcome.RUNS_ON)


class Foresight(NamedTuple):
    """The simulation's end: how, after how many steps, and where; and what the way there cost.

    ``exposure`` is the trapezoid integral of the level along the simulated
    steps, so ``steps * step + LAMBDA * exposure`` is the foreseen path's ``J``.
    """

    outcome: Outcome
    steps: int
    x: float
    y: float
    exposure: float = 0.0


@numba.njit(cache=True, nogil=True)
def _simulate(
    packed: np.ndarray,
    x: float,
    y: float,
    gx: float,
    gy: float,
    gain: float,
    step: float,
    tol: float,
    window: int,
    patience: int,
    budget: int,
    box: np.ndarray,
) -> tuple[int, int, float, float, float]:
    # mirrors Stepper.check / follow / _watch, advisory by advisory
    best = math.inf
    exposure = 0.0
    last = -1.0
    since = 0
    ring = np.empty((window, 2))
    count = 0
    head = 0
    for k in range(budget + 1):
        if not (math.isfinite(x) and math.isfinite(y)):
            return _STOPS, k, x, y, exposure
        dist = math.hypot(gx - x, gy - y)
        if dist <= tol:
            if last >= 0.0:  # the level at the goal itself, for the last step
                exposure += 0.5 * step * (last + kernels.point_level(packed, x, y))
            return _ARRIVES, k, x, y, exposure
        if not (box[0] <= x <= box[2] and box[1] <= y <= box[3]):
            return _LEAVES, k, x, y, exposure
        fx, fy, lv, norm = kernels.point_descent(packed, x, y, gx, gy, gain)
        if last >= 0.0:
            exposure += 0.5 * step * (last + lv)
        last = lv
        if not math.isfinite(norm):
            return _STOPS, k, x, y, exposure
        if norm == 0.0:
            return _TRAPPED, k, x, y, exposure
        if dist < best - tol:
            best = dist
            since = 0
        else:
            since += 1
            if since >= patience:
                return _TRAPPED, k, x, y, exposure
        if count == window and math.hypot(x - ring[head, 0], y - ring[head, 1]) < 0.2 * window * step:
            return _TRAPPED, k, x, y, exposure
        ring[head, 0] = x
        ring[head, 1] = y
        head = (head + 1) % window
        count = min(count + 1, window)
        if k == budget:
            break
        x += step * (-fx / norm)
        y += step * (-fy / norm)
    return _RUNS_ON, budget, x, y, exposure


def simulate(
    field: ThreatField,
    start: tuple[float, float],
    goal: tuple[float, float],
    gain: float,
    params: Resolved,
    bounds: Bounds | None = None,
    budget: int | None = None,
) -> Foresight:
    """Plain descent from ``start``, judged by a fresh stepper's rules.

    Args:
        field: the threats in force.
        start, goal: metres.
        gain: the stepper's ``delta / ||goal - x0||^2``.
        params: the stepper's resolved parameters (step, tolerance, trap windows).
        bounds: the mission bounds, if any.
        budget: most steps simulated; default ``params.max_iter``.  Never
            more than ``FORESIGHT_MAX_STEPS``.
    """
    limit = params.max_iter if budget is None else budget
    limit = min(limit, FORESIGHT_MAX_STEPS)
    if bounds is None:
        box = np.array([-math.inf, -math.inf, math.inf, math.inf])
    else:
        (x0, y0), (x1, y1) = bounds
        box = np.array([x0, y0, x1, y1], dtype=np.float64)
    code, steps, x, y, exposure = _simulate(
        field.packed,
        float(start[0]),
        float(start[1]),
        float(goal[0]),
        float(goal[1]),
        gain,
        params.step,
        params.tolerance,
        params.trap_window,
        params.progress_window,
        limit,
        box,
    )
    return Foresight(_OUTCOMES[code], steps, x, y, exposure)
