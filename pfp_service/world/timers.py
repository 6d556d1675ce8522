"""The world's timers: one heap of (when, kind, id), so a tick costs O(what is due), never a scan.

A timer is a reminder, not a verdict: the world looks again at what it names
when it comes due (a unit heard from since, a threat put again) and a stale
reminder does nothing.  Pure values: ``now`` is a parameter.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator

__all__ = ["Timers"]


class Timers:
    """A heap of timers in the order they fall due; timers due at the same time in the order set."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, str, str]] = []  # (when, seq, kind, id)
        self._seq = 0

    def __len__(self) -> int:
        return len(self._heap)

    def set(self, when: float, kind: str, ident: str) -> None:
        """Remind the world of ``kind`` on ``ident`` at ``when``."""
        self._seq += 1
        heapq.heappush(self._heap, (when, self._seq, kind, ident))

    def next_due(self) -> float | None:
        """When the earliest timer falls due (``None``: none is set)."""
        return self._heap[0][0] if self._heap else None

    def due(self, now: float) -> Iterator[tuple[str, str]]:
        """Pop each timer due at ``now`` (``(kind, id)``), timers set while iterating included."""
        while self._heap and self._heap[0][0] <= now:
            _, _, kind, ident = heapq.heappop(self._heap)
            yield kind, ident
