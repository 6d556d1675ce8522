"""Advice for many units under one field: one vectorised gradient kernel, then each unit's own rule.

``advise_many`` is what the live tick and the look-ahead call: the gradients
of every unit in one compiled call (culled, ``core.cull``), then each
stepper's verdict (``Stepper.follow`` for plain descent, ``Stepper.advise``
where the unit is in a keep-out zone or on a route), identical to calling
``Stepper.advise`` unit by unit.
"""

from __future__ import annotations

import numpy as np

from pfp_service.core import kernels
from pfp_service.core.advice import Advice, Need, StepStatus
from pfp_service.core.cull import MIN_THREATS, CullIndex
from pfp_service.core.stepper import Stepper
from pfp_service.core.threat import ThreatField

__all__ = ["advise_many"]


def advise_many(
    steppers: list[Stepper], field: ThreatField, positions: np.ndarray, cull: CullIndex | None = None
) -> list[Advice]:
    """``advise`` for many units under one field, with one vectorised kernel call.

    Args:
        steppers: one stepper per unit.
        field: the threats in force.
        positions: ``(N, 2)`` reported positions, row i for ``steppers[i]``.
        cull: ``field``'s cull index: only nearby threats are evaluated, within
            the bound ``core.cull`` proves (used from ``cull.MIN_THREATS`` threats).

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
    rows = out.tolist()
    coords = pts.tolist()
    # a unit in a keep-out zone, or whose goal is in one, is judged by ``advise`` (``Stepper._zoned``)
    zoned = (field.zones.contains(pts) | field.zones.contains(goals)).tolist() if field.zones else [False] * n
    result = []
    for s, (x, y), (fx, fy, level, norm), z in zip(steppers, coords, rows, zoned):
        if z:
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
            result.append(s.advise(field, x, y))
        else:
            if s._foresee:  # deferred: ask for the look-ahead and descend meanwhile, as ``advise`` does
                s._foresee = False
                s.pending = Need("foresee", x, y)
            if s._run is not None:  # on a route: the batch gave this position's level
                result.append(s._escaping(field, x, y, level, grad=(fx, fy, level, norm)))
            else:
                result.append(s.follow(x, y, fx, fy, level, norm, field))
    return result
