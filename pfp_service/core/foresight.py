"""Looking ahead: simulate a unit's own plain descent, with the stepper's trap rules, before it moves.

Plain descent cannot see a trap until it is inside it: by then the walk in is
spent, and so is the walk back out.  Under ``escape: auto`` the stepper
therefore runs this simulation once when its goal is set and once after each
world change (never per advisory): plain descent from the unit's position,
exactly as ``Stepper.advise`` would advise it for a unit that moves to each
``Advice.to``: the same rule, ``steprule.judge`` (arrival, bounds, the final
approach, stall and no-progress), called advisory by advisory.  If
the simulation ends ``trapped`` or out of bounds, the stepper commits to a way
round before walking in (``escape.Escaper.foresee``).

It is a prediction, not a promise: a live unit drifts from its advice, and a
trap the simulation missed is still caught, and escaped, when it happens.
Each step's gradient is culled as the live tick's is (``cull``: the threats
the unit's cell lists where the proven bound holds, every threat elsewhere),
so among many threats a step costs its neighbours, not the whole field.
It costs one compiled loop, about 0.1 ms for a few hundred steps, and never
more than ``FORESIGHT_MAX_STEPS`` steps (a few ms): the simulation runs on the
planning thread that serves every unit, and a goal given with a tiny explicit
step could otherwise ask for billions.  A simulation cut short ends
``runs_on``, which foresees no trap: the unit descends as under ``escape: none``
and a trap is still caught when it happens.
"""

from __future__ import annotations

import dataclasses
import math
from enum import StrEnum
from typing import NamedTuple

import numba
import numpy as np

from pfp_service.core import cull, kernels, steprule
from pfp_service.core.params import Resolved
from pfp_service.core.threat import ThreatField

__all__ = [
    "FORESIGHT_MAX_STEPS",
    "TOLERANCE_SHARE",
    "Foresight",
    "Outcome",
    "coarser",
    "resolution",
    "simulate",
]

FORESIGHT_MAX_STEPS = 20_000
STEPS_PER_LENGTH = 4.0  # a descent's path is rarely more than this many straight lines long
TOLERANCE_SHARE = 0.75  # core.params' derived tolerance, as a share of the step
_NO_TRAIL = np.empty((0, 2))

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
    path: np.ndarray | None = (
        None  # the simulated positions ``(steps + 1, 2)``, when asked for (``keep_path``)
    )
    step: float = 0.0  # the step simulated: the stepper's, or coarser (``resolution``)


@numba.njit(cache=True, nogil=True)
def _simulate(  # type: ignore[no-untyped-def]
    packed, edges, offsets, circles, boxes, unit, x, y, budget,
    culled, grid, indptr, indices, cell_need, need_outside, trail,
):  # fmt: skip
    # the stepper's own advisories: steprule.judge, advisory by advisory, and the exposure on the way;
    # each gradient culled as the live tick's is (cull.py: the threats the cell lists, where the
    # proven bound holds; every threat elsewhere)
    exposure = 0.0
    last = -1.0
    seg = 0.0  # the last step's length
    pts = np.empty((1, 2))
    goals = np.empty((1, 2))
    goals[0, 0] = unit[steprule.GOAL_X]
    goals[0, 1] = unit[steprule.GOAL_Y]
    gains = np.empty(1)
    gains[0] = unit[steprule.GAIN]
    out = np.empty((1, 4))
    flags = np.zeros(1, dtype=np.bool_)
    keep = trail.shape[0] > budget  # the caller asked for the path: position k goes to trail[k]
    for k in range(budget + 1):
        if keep:
            trail[k, 0] = x
            trail[k, 1] = y
        if culled:
            pts[0, 0] = x
            pts[0, 1] = y
            cull._culled_row(
                packed, pts, goals, gains, grid, indptr, indices, cell_need, need_outside, out, flags, 0
            )
            if flags[0]:
                kernels._descent_row(packed, pts, goals, gains, out, 0)
            fx, fy, lv, norm = out[0, 0], out[0, 1], out[0, 2], out[0, 3]
        else:
            fx, fy, lv, norm = kernels.point_descent(
                packed, x, y, unit[steprule.GOAL_X], unit[steprule.GOAL_Y], unit[steprule.GAIN]
            )
        code, _dx, _dy, _dist, move, tx, ty = steprule.judge_zoned(
            unit, edges, offsets, circles, boxes, x, y, fx, fy, norm
        )
        if code == steprule.BAD_POSITION:
            return _STOPS, k, x, y, exposure
        if code == steprule.OUT_OF_BOUNDS:
            return _LEAVES, k, x, y, exposure
        if last >= 0.0:  # the trapezoid of the step that came here
            exposure += 0.5 * seg * (last + lv)
        if code == steprule.ARRIVED:
            return _ARRIVES, k, x, y, exposure
        last = lv
        if code == steprule.BAD_GRADIENT:
            return _STOPS, k, x, y, exposure
        if code != steprule.GO:
            return _TRAPPED, k, x, y, exposure
        if k == budget:
            break
        seg = move
        x = tx
        y = ty
    return _RUNS_ON, budget, x, y, exposure


def resolution(params: Resolved, dist: float, budget: int) -> Resolved:
    """``params``, or a coarser copy whose step reaches ``dist`` within ``budget / STEPS_PER_LENGTH`` steps.

    ``max_iter`` becomes the budget, and the tolerance grows with
    the step up to ``TOLERANCE_SHARE`` of it (the derived share: an explicit
    tolerance is never made finer); the trap windows count steps, so they
    keep their meaning at any step.
    """
    if not (dist > 0.0 and math.isfinite(dist)) or params.step * budget >= STEPS_PER_LENGTH * dist:
        return params
    step = max(STEPS_PER_LENGTH * dist / budget, progress_floor(params))
    return dataclasses.replace(coarser(params, step), max_iter=budget)


def progress_floor(params: Resolved) -> float:
    """The finest step at which the no-progress rule can be met: ``progress_window`` steps cover two tolerances.

    A mission whose tolerance dwarfs its step (one restored with a denormal
    step) would otherwise be judged trapped for lack of progress at once.
    """
    window = max(params.progress_window, 1)
    return 2.0 * params.tolerance / window


def coarser(params: Resolved, step: float) -> Resolved:
    """``params`` at the coarser ``step``: the tolerance grows with it up to its derived share, never finer."""
    scale = step / params.step
    return dataclasses.replace(
        params,
        step=step,
        tolerance=max(params.tolerance, min(params.tolerance * scale, TOLERANCE_SHARE * step)),
    )


def simulate(
    field: ThreatField,
    start: tuple[float, float],
    goal: tuple[float, float],
    gain: float,
    params: Resolved,
    bounds: Bounds | None = None,
    budget: int | None = None,
    keep_path: bool = False,
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
        keep_path: return the simulated positions too (``Foresight.path``).

    A step so fine that the way to the goal would not fit in the budget is
    simulated at a coarser one (``resolution``): descent is scale-free, so
    the coarser simulation foresees the same trap or the same arrival, where
    the fine one would run out of steps half way and foresee nothing.
    """
    params = resolution(params, math.hypot(goal[0] - start[0], goal[1] - start[1]), FORESIGHT_MAX_STEPS)
    limit = params.max_iter if budget is None else budget
    limit = min(limit, FORESIGHT_MAX_STEPS)
    unit = steprule.unit(
        goal, gain, params.tolerance, params.step, bounds, params.trap_window, params.progress_window
    )
    if params.trap_window > 0:  # room for the whole watch at once: at most the steps simulated
        ring = min(params.trap_window, limit + 1)
        unit = np.concatenate([unit[: steprule.RING], np.zeros(2 * ring)])
    index = cull.index_of(field)
    if index is not None:
        grid = (index.origin[0], index.origin[1], index.cell, index.nx, index.ny)
        args = (
            grid,
            index.indptr,
            index.indices,
            index.cell_bound / cull.RELATIVE_BOUND,
            index.bound / cull.RELATIVE_BOUND,
        )
    else:
        args = ((0.0, 0.0, 1.0, 1, 1), np.zeros(2, np.int64), np.zeros(0, np.int64), np.zeros(1), 0.0)
    trail = np.empty((limit + 1, 2)) if keep_path else _NO_TRAIL
    code, steps, x, y, exposure = _simulate(
        field.packed,
        *field.zones.packed(),
        unit,
        float(start[0]),
        float(start[1]),
        limit,
        index is not None,
        *args,
        trail,
    )
    path = trail[: steps + 1] if keep_path else None
    return Foresight(_OUTCOMES[code], steps, x, y, exposure, path, params.step)
