"""The world's bulkheads: a failure inside ``World.apply`` belongs to the input, timer or unit that caused it.

``fault`` drops what failed (a unit named loses its goal and is told
``no_goal``; a record too broken to reset is forgotten), rejects it on its
key, and logs it at most once a minute per key (``Limits.fault``);
``reject`` counts every rejection and sends at most ``REJECTS_PER_S``
events a second per kind of key.  Pure values: ``now`` is the batch's.
"""

from __future__ import annotations

from collections.abc import Mapping

from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.world import events as ev
from pfp_service.world import steering
from pfp_service.world.events import Batch, WorldSettings
from pfp_service.world.limits import Limits
from pfp_service.world.units import UnitRecord, Units

__all__ = ["Bulkheads"]


class Bulkheads:
    """Faults and rejections of one world (its settings, records, the units' writer and its limits)."""

    def __init__(self, settings: WorldSettings, units: Mapping[str, UnitRecord], book: Units, limits: Limits):
        self.settings, self._units, self._book, self._limits = settings, units, book, limits

    def key(self, kind: keys.KeyKind, ident: str) -> str:
        """The key of ``kind`` for ``ident``, spelled even for an id ``keys`` would refuse."""
        return keys.TEMPLATES[kind].format(mission=self.settings.mission, id=ident)

    def fault(
        self,
        b: Batch,
        key: str,
        unit: str | None,
        kind: keys.KeyKind | None,
        exc: BaseException,
        error: tuple[str, str, str] | None = None,
    ) -> None:
        """Something failed inside the world on ``key``'s account: drop it, reject it, log it once a minute.

        The unit named loses its goal (a goal it cannot be guided to is
        refused, not retried at every report) and gets ``no_goal``.
        """
        rec = self._units.get(unit) if unit is not None else None
        said = ""
        if rec is not None:
            try:
                said = "; the unit's goal was dropped" if rec.goal is not None else ""
                if rec.goal is not None or rec.shared is not None:
                    self._book.drop_mission(
                        rec, "goal dropped: the planner failed on it (see its fault event)"
                    )
                if rec.position is not None and not rec.stale:  # told so in this batch (``World._direct``)
                    b.dirty.add(rec.id)
            except Exception:  # a record too broken to reset: forget it (a report makes it afresh)
                self._book.discard(rec)
        name, detail, at = error if error is not None else (type(exc).__name__, str(exc)[:200], ev.where(exc))
        reason = f"not applied: {name} inside the planner ({detail}); this input alone was dropped{said}"
        self.reject(key, InputError("$", reason), b, kind)
        logged = self._limits.fault(
            key, b.now
        )  # the operator's log: once a minute per key, never a traceback
        if logged is not None:
            b.out.faults.append(ev.Fault(logged[0], name, detail, at, logged[1]))

    def unit_fault(
        self, b: Batch, rec: UnitRecord, exc: BaseException, error: tuple[str, str, str] | None = None
    ) -> None:
        """A failure on ``rec``'s account, rejected on its goal's key."""
        self.fault(b, self.key(keys.KeyKind.UNIT_GOAL, rec.id), rec.id, keys.KeyKind.UNIT_GOAL, exc, error)

    def reject(self, key: str, err: InputError, b: Batch, kind: keys.KeyKind | None) -> None:
        """Count every rejection; send at most ``REJECTS_PER_S`` events a second per ``kind`` of key."""
        held = self._limits.reject(kind, b.now)
        if held is not None:
            b.out.events.append(steering.rejected(key, err, self.settings.planner_id, held))
