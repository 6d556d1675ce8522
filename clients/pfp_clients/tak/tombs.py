"""The bridge's tombstones: deleted markers a TAK server's replay must not revive, bounded fairly.

A TAK server keeps every marker until its stale time and replays it on each
connection, deletes or not.  A tombstone (``Tombstone``) refuses those replays
until the marker's stale time.  Memory is bounded (``MAX_TOMBSTONES``), and
fairly: each source (the link a delete came by) holds at most
``MAX_TOMBSTONES_PER_SOURCE``, and nothing buried is pushed out by what comes
after it.  A source at its share keeps what it has and buries no more until
some expire; a full bridge makes room only from the source holding the most
(its newest).  So a flood of deletes with stale times years out, which used to
evict the earliest-ending (the legitimate) tombstones, costs only its own.

Sans-I/O: times are passed in; ``log`` is the only output.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["MAX_TOMBSTONES", "MAX_TOMBSTONES_PER_SOURCE", "Tombstone", "Tombstones"]

MAX_TOMBSTONES = 10_000
MAX_TOMBSTONES_PER_SOURCE = 2_500


@dataclass(frozen=True, slots=True)
class Tombstone:
    """A deleted marker: versions sent at or before ``after`` are refused until ``until`` (Unix s).

    ``source``: the link the delete came by (``""``: not known, as in an older file).
    """

    after: float
    until: float
    source: str = ""


class Tombstones:
    """Marker uid -> ``Tombstone``, with a count per source and a version bumped on every change."""

    def __init__(self, log: Callable[[str], None] = lambda _m: None) -> None:
        self.by_uid: dict[str, Tombstone] = {}
        self.version = 0  # the driver saves them when it moves
        self.refused = 0  # deletes not kept: their source was at its share
        self._log = log
        self._per_source: dict[str, int] = {}

    def get(self, uid: str) -> Tombstone | None:
        return self.by_uid.get(uid)

    def bury(self, uid: str, after: float, until: float, now: float, source: str = "") -> None:
        """Refuse versions of ``uid`` sent at or before ``after`` until ``until``, if there is fair room."""
        if until <= now:
            return
        old = self.by_uid.get(uid)
        if old is not None:  # the same marker deleted again: one tombstone, where it was
            self.by_uid[uid] = Tombstone(max(after, old.after), max(until, old.until), old.source)
            self.version += 1
            return
        if not self._room_for(source):
            self.refused += 1
            if self.refused in (1, 100, 10_000):
                self._log(
                    f"tombstones: {source or 'a source'} is at its share ({MAX_TOMBSTONES_PER_SOURCE}); "
                    f"{self.refused} deletes not kept, the older ones are"
                )
            return
        self.by_uid[uid] = Tombstone(after, until, source)
        self._per_source[source] = self._per_source.get(source, 0) + 1
        self.version += 1

    def extend(self, uid: str, until: float) -> None:
        """A replay of ``uid`` stale later than its tombstone: the tombstone lasts as long."""
        t = self.by_uid[uid]
        self.by_uid[uid] = Tombstone(t.after, until, t.source)
        self.version += 1

    def lift(self, uid: str) -> None:
        """``uid`` sent after its delete: a new marker, no longer refused."""
        t = self.by_uid.pop(uid)
        self._count_out(t.source)
        self.version += 1

    def expire(self, now: float) -> None:
        for uid in [u for u, t in self.by_uid.items() if t.until <= now]:
            self.lift(uid)

    def _count_out(self, source: str) -> None:
        left = self._per_source[source] - 1
        if left:
            self._per_source[source] = left
        else:
            del self._per_source[source]

    def _room_for(self, source: str) -> bool:
        mine = self._per_source.get(source, 0)
        if mine >= MAX_TOMBSTONES_PER_SOURCE:
            return False
        if len(self.by_uid) < MAX_TOMBSTONES:
            return True
        biggest = max(self._per_source, key=self._per_source.__getitem__)
        if self._per_source[biggest] <= mine + 1:
            return False  # no source holds more than this one would: nothing fair to take
        newest = next(u for u in reversed(self.by_uid) if self.by_uid[u].source == biggest)
        self.lift(newest)
        return True
