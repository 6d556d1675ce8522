"""Look-ahead bookkeeping: the positions a direction predicts, from where its step ends, kept on the wire's map.

A unit en route gets ``n`` predicted positions with its direction: the end of
the step it is advised (``Advice.to``, ``steprule.judge``) and ``n - 1`` more
batched kernel steps (``plan.predict_many``; ghosts for units on a route).  A
unit whose verdict is terminal (arrived, trapped) gets none.  A track is cut
at its first point off the wire's map.  Pure values in and out.
"""

from __future__ import annotations

import itertools

import numpy as np

from pfp_service.core import Stepper, ThreatField
from pfp_service.core.cull import CullIndex
from pfp_service.core.plan import predict_many
from pfp_service.core.stepper import Advice
from pfp_service.errors import FINITE_LIMIT

__all__ = ["lookahead", "within_map"]

Track = list[tuple[float, float]]


def lookahead(
    steppers: list[Stepper], advices: list[Advice], fld: ThreatField, n: int, cull: CullIndex | None
) -> list[Track]:
    """The ``n`` predicted positions of each unit, in the order given (empty for a terminal verdict or ``n <= 0``)."""
    result: list[Track] = [[] for _ in steppers]
    if n <= 0:
        return result
    idx = [i for i, a in enumerate(advices) if not a.status.terminal]
    if not idx:
        return result
    starts = np.array([advices[i].to for i in idx])  # where the step advised ends (steprule.judge)
    tracks = predict_many([steppers[i] for i in idx], fld, starts, n - 1, cull)
    for i, track in zip(idx, tracks):
        result[i] = track
    return result


def within_map(track: Track) -> Track:
    """The look-ahead up to its first point off the wire's map (±``FINITE_LIMIT``, or not a number)."""
    lim = FINITE_LIMIT
    if all(-lim <= c <= lim for c in itertools.chain.from_iterable(track)):
        return track
    for i, (x, y) in enumerate(track):
        if not (-lim <= x <= lim and -lim <= y <= lim):
            return track[:i]
    return track
