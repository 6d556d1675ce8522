"""Look-ahead bookkeeping: the positions a direction predicts, from where its step ends, kept on the wire's map.

A unit en route gets ``n`` predicted positions with its direction: the end of
the step it is advised (``Advice.to``, ``steprule.judge``) and ``n - 1`` more
batched kernel steps (``plan.predict_many``; ghosts for units on a route).  A
unit whose verdict is terminal (arrived, trapped) gets none.  A track is cut
at its first point off the wire's map.  Pure values in and out.
"""

from __future__ import annotations

import itertools
from collections.abc import Collection, Mapping
from typing import TYPE_CHECKING

import numpy as np

from pfp_service.core import Stepper, ThreatField
from pfp_service.core.cull import CullIndex
from pfp_service.core.plan import predict_many
from pfp_service.core.stepper import Advice
from pfp_service.errors import FINITE_LIMIT

if TYPE_CHECKING:
    from pfp_service.world.world_records import UnitRecord

__all__ = ["Owed", "lookahead", "owed_share", "within_map"]

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


# A wave's unit sent its direction without points: (unit, its advice, stepper, its version, seq).
Owed = tuple["UnitRecord", Advice, Stepper, int, int | None]


def owed_share(
    owed: list[Owed], dirty: Collection[str], units: Mapping[str, UnitRecord], limit: int
) -> tuple[list[tuple[UnitRecord, Advice]], list[Owed]]:
    """The next ``limit`` of a wave's units still owed their points, untouched since; and the rest, still owed.

    A unit heard (``dirty``), re-advised or gone since its direction went out
    is answered otherwise and dropped; the points come from the advice it
    was sent, so a wave paid in chunks gives what one pass would.
    """
    later: list[tuple[UnitRecord, Advice]] = []
    for i, (r, a, stepper, version, seq) in enumerate(owed):
        if r.id in dirty or units.get(r.id) is not r or not r.live() or r.seq != seq:
            continue  # heard, gone or stale since: answered otherwise
        if r.stepper is not stepper or stepper.version != version:
            continue  # a new goal or world since: its direction went out afresh
        if len(later) == limit:
            return later, owed[i:]  # checked again when their turn comes
        later.append((r, a))
    return later, []
