"""A wave's re-directions paid in chunks: the units a change reaches, told at most ``WAVE_PER_TICK`` an ``apply``.

A threat put (or its window landed over terrain) re-judges every unit it
reaches in one ``apply`` (cheap: a version bumped, a job superseded), but
steering them all there held the loop for the whole wave: a state that
came meanwhile waited for it (the bystanders' tail, issue 32).  So a wave
larger than ``WAVE_PER_TICK`` directs its first share in the ``apply`` that
changed the world, the units nearest the change first, and owes the rest
(``Wave``): each later ``apply`` directs the next share, the states that
came meanwhile with it, until none is owed (``World.wave_pending``).  A unit
heard, re-judged again, given a new goal or gone since is answered
otherwise and dropped from the queue.  Pure values: no clock, no I/O.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from pfp_service.core.stepper import Stepper

if TYPE_CHECKING:
    from pfp_service.core import Threat
    from pfp_service.world.world_records import UnitRecord

__all__ = ["WAVE_PER_TICK", "Wave", "nearest_first", "split"]

# units of a wave steered an ``apply`` (figures: docs/operations.md, "The wave first")
WAVE_PER_TICK = 64


def nearest_first(recs: Sequence[UnitRecord], centres: Sequence[tuple[float, float]]) -> list[UnitRecord]:
    """``recs`` (each with a position) ordered by distance to the nearest of ``centres``, nearest first (stable)."""
    if not centres or len(recs) < 2:
        return list(recs)
    pos = np.array([r.position for r in recs], dtype=float).reshape(-1, 2)
    c = np.array(centres, dtype=float).reshape(-1, 2)
    d = np.hypot(pos[:, None, 0] - c[None, :, 0], pos[:, None, 1] - c[None, :, 1]).min(axis=1)
    d = np.where(np.isfinite(d), d, np.inf)
    return [recs[i] for i in np.argsort(d, kind="stable")]


def split(
    hit: Sequence[UnitRecord],
    touched: Sequence[Threat],
    zones: Sequence[tuple[float, float, float, float]],
    dirty: Collection[str],
    limit: int,
) -> tuple[list[UnitRecord], list[UnitRecord]]:
    """The units a change reached: those to steer now (at most ``limit``, and every one heard in this batch,
    ``dirty``) and those owed, nearest the threats ``touched`` and the ``zones`` (boxes) changed first."""
    if len(hit) <= limit:
        return list(hit), []
    centres = [(float(t.xi[0]), float(t.xi[1])) for t in touched]
    centres += [((z[0] + z[2]) / 2.0, (z[1] + z[3]) / 2.0) for z in zones]
    ordered = nearest_first(hit, centres)
    now = ordered[:limit] + [r for r in ordered[limit:] if r.id in dirty]
    return now, [r for r in ordered[limit:] if r.id not in dirty]


class Wave:
    """The units of a wave still owed their direction, in the order they are to get it."""

    def __init__(self) -> None:
        # by unit: the record, its stepper, the version it was re-judged at and its report's seq then
        self._owed: dict[str, tuple[UnitRecord, Stepper, int, int | None]] = {}  # in the queue's order

    def __bool__(self) -> bool:
        return bool(self._owed)

    def __len__(self) -> int:
        return len(self._owed)

    def owe(self, recs: Sequence[UnitRecord]) -> None:
        """Owe ``recs`` (each re-judged, with a stepper) their direction, after those owed already."""
        for rec in recs:
            st = rec.stepper
            if st is not None:
                self._owed.pop(rec.id, None)
                self._owed[rec.id] = (rec, st, st.version, rec.seq)

    def ids(self) -> list[str]:
        """The units owed (a replan event names them with those told at once)."""
        return list(self._owed)

    def take(self, dirty: Collection[str], units: Mapping[str, UnitRecord], limit: int) -> list[str]:
        """The next ``limit`` units owed and still as they were re-judged; each is owed no longer.

        One ``dirty`` already (heard in this batch), heard since it was owed,
        gone, stale, or with another stepper or version since is answered
        otherwise: dropped.
        """
        got: list[str] = []
        for uid in list(self._owed):
            if len(got) >= limit:
                break
            rec, st, version, seq = self._owed.pop(uid)
            if uid in dirty or units.get(uid) is not rec or not rec.live() or rec.seq != seq:
                continue
            if rec.stepper is not st or st.version != version or rec.position is None:
                continue
            got.append(uid)
        return got
