"""Advice for many units under one field: one vectorised gradient kernel, then each unit's own rule.

``advise_many`` is what the live tick and the look-ahead call: the gradients
of every unit in one compiled call (culled, ``core.cull``), then each
stepper's verdict (``Stepper.follow`` for plain descent, ``Stepper.advise``
where the unit is in a keep-out zone or on a route), identical to calling
``Stepper.advise`` unit by unit.
"""

from __future__ import annotations

import math

import numpy as np

from pfp_service.core import kernels
from pfp_service.core.advice import Advice, Need, StepStatus
from pfp_service.core.cull import MIN_THREATS, CullIndex
from pfp_service.core.stepper import Stepper
from pfp_service.core.threat import ThreatField
from pfp_service.core.tracking import Route

__all__ = ["advise_many"]

_OWN = (Route.NONE, Route.DESCENT)  # routes whose heading is the batch's (pushed) descent
SIDE_CLEAR = math.sin(math.radians(15.0))  # a push this near the heading's line has no clear side


def advise_many(
    steppers: list[Stepper],
    field: ThreatField,
    positions: np.ndarray,
    cull: CullIndex | None = None,
    push: np.ndarray | None = None,
) -> list[Advice]:
    """``advise`` for many units under one field, with one vectorised kernel call.

    Args:
        steppers: one stepper per unit.
        field: the threats in force.
        positions: ``(N, 2)`` reported positions, row i for ``steppers[i]``.
        cull: ``field``'s cull index: only nearby threats are evaluated, within
            the bound ``core.cull`` proves (used from ``cull.MIN_THREATS`` threats).
        push: ``(N, 2)`` an extra gradient per unit in units of its field's
            slope where it stands (dispersion, ``core.dispersion``): row i's
            descent (plain, or a tracked descent) follows ``grad f + |grad f|
            push[i]`` (square across the push where that would turn it
            back, ``_pushed``).  A unit steered otherwise (another route, a keep-out
            zone) turns its heading ``h`` to ``h - push[i]`` (normalised), the
            same sum with the heading as the field's slope, for one step.

    Returns:
        One ``Advice`` per stepper, in order; identical to calling ``advise`` one by one.
    """
    pts = np.ascontiguousarray(positions, dtype=np.float64).reshape(-1, 2)
    n = len(steppers)
    goals = np.array([s.goal for s in steppers], dtype=np.float64).reshape(n, 2)
    gains = np.fromiter([s.goal_gain for s in steppers], dtype=np.float64, count=n)
    out = np.empty((n, 4))
    if cull is not None and len(field) >= MIN_THREATS:
        cull.descent(pts, goals, gains, out)
    else:
        kernels.descent_many(field.packed, pts, goals, gains, out)
    if push is not None:  # only rows with a neighbour near: a unit alone is advised as without dispersion
        near = push.any(axis=1)
        out[near, :2] = _pushed(out[near, :2], out[near, 3:4], push[near])
        out[near, 3] = np.hypot(out[near, 0], out[near, 1])
    rows = out.tolist()
    coords = pts.tolist()
    # a unit in a keep-out zone, or whose goal is in one, is judged by ``advise`` (``Stepper._zoned``)
    zoned = (field.zones.contains(pts) | field.zones.contains(goals)).tolist() if field.zones else [False] * n
    result: list[Advice] = []
    alone: list[int] = []  # advised by the stepper's own rule, not from the batch's gradient
    for s, (x, y), (fx, fy, level, norm), z in zip(steppers, coords, rows, zoned):
        if z:
            alone.append(len(result))
            result.append(s.advise(field, x, y))
            continue
        if s._terminal is None and s._run is None:
            if not s._foresee:  # plain descent: one judge call
                result.append(s.follow(x, y, fx, fy, level, norm, field))
                continue
            if s.defer and not field.zones:  # a wave's unit: ask for the look-ahead, descend, one call
                result.append(s.foresee_follow(x, y, fx, fy, level, norm, field))
                continue
        early = s.check(x, y)
        if early is not None:
            result.append(early._replace(level=level) if early.status is StepStatus.TRAPPED else early)
        elif s._foresee and not s.defer:  # looking ahead inline (a preview): not the batch's descent
            alone.append(len(result))
            result.append(s.advise(field, x, y))
        else:
            if s._foresee:  # deferred: ask for the look-ahead and descend meanwhile, as ``advise`` does
                s._foresee = False
                s.pending = Need("foresee", x, y)
            if s._run is not None:  # on a route: the batch gave this position's level
                result.append(s._escaping(field, x, y, level, grad=(fx, fy, level, norm)))
            else:
                result.append(s.follow(x, y, fx, fy, level, norm, field))
    if push is not None:
        _turn(result, steppers, coords, push, alone)
    return result


def _pushed(grad: np.ndarray, norm: np.ndarray, push: np.ndarray) -> np.ndarray:
    """Each unit's gradient ``grad`` (``(M, 2)``, of length ``norm``) with its ``push``: ``grad + norm push``,
    or where that would turn its descent back (against the unpushed one), ``grad`` less its part along
    the push, at its length: square across the push, on the side the unit was going.

    A pushed descent never turns back, as a route's heading does not (``_turn``): pushed back by a
    neighbour between it and its goal (within 4/3 separations the push outweighs the pull), a unit
    was herded away from its goal for as long as that neighbour came on, or stepped back and forth
    where push and pull balanced, until a deadlock was found (the gaps crowd's seed 21, issue 33:
    ``u0170`` herded from 119 to 205 m off its goal, 86 s from the deadlock's start to cleared); it now
    goes round the neighbour.  Head on (no part across the push), the sum stands.
    """
    total: np.ndarray = grad + norm * push
    back = np.flatnonzero((total * grad).sum(axis=1) < 0.0)
    if not len(back):
        return total
    p = push[back] / np.hypot(push[back, 0], push[back, 1])[:, None]
    across = grad[back] - (grad[back] * p).sum(axis=1)[:, None] * p
    length = np.hypot(across[:, 0], across[:, 1])[:, None]
    side = length[:, 0] > 1e-9 * norm[back, 0]
    total[back[side]] = across[side] / length[side] * norm[back[side]]
    return total


def _turn(
    result: list[Advice],
    steppers: list[Stepper],
    coords: list[list[float]],
    push: np.ndarray,
    alone: list[int],
) -> None:
    """Turn, in place, each advice not made from the pushed gradient by its unit's push (``advise_many``).

    The heading becomes ``h - push`` normalised, or where that would turn
    back along the route, square across the push on ``h``'s side (the unit
    goes round its neighbours, not back), or on the goal's side where the
    push runs along ``h`` (``_across``); the advice holds for one step at
    most (to where that step ends): the route or the zone rule judges again
    at the next report.
    """
    again, pushes = set(alone), push.tolist()
    for k, adv in enumerate(result):
        if adv.status.terminal or not (k in again or adv.route not in _OWN):
            continue
        px, py = pushes[k]
        if px == 0.0 and py == 0.0:
            continue
        vx, vy = adv.dx - px, adv.dy - py
        if vx * adv.dx + vy * adv.dy < 0.0:  # not back along a route: round the neighbours, across the push
            x, y = coords[k]
            gx, gy = steppers[k].goal
            vx, vy = _across(px, py, adv.dx, adv.dy, gx - x, gy - y)
        v = math.hypot(vx, vy)
        if not v > 0.0:
            continue
        r = min(adv.reach, steppers[k].params.step)
        dx, dy = vx / v, vy / v
        x, y = coords[k]
        result[k] = adv._replace(dx=dx, dy=dy, reach=r, to_x=x + r * dx, to_y=y + r * dy)


def _across(px: float, py: float, hx: float, hy: float, gx: float, gy: float) -> tuple[float, float]:
    """Square across the push ``(px, py)``: on the heading ``(hx, hy)``'s side, or where the push runs
    along the heading (no clear side), on the side of the goal ``(gx, gy)`` (from the unit).

    The heading's side alone flipped at each report where the route ran
    straight at the neighbours (the sign of a cross product near 0): 5 m
    one way, 5 m back, for as long as the push stayed on the route's line.
    """
    p = math.hypot(px, py)
    cross = px * hy - py * hx
    if not abs(cross) > SIDE_CLEAR * p * math.hypot(hx, hy):
        goal = px * gy - py * gx
        cross = goal if goal != 0.0 else cross
    return (-py, px) if cross >= 0.0 else (py, -px)
