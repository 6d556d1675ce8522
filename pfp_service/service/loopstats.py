"""The planning loop's own upkeep: its latency figures and handing freed memory back to the OS."""

from __future__ import annotations

import collections
import ctypes
import math
import threading
from typing import Any

__all__ = ["Latency", "Trim"]

TRIM_AFTER = 256  # units forgotten before freed memory is handed back to the OS
TRIM_QUIET_S = 1.0  # ... once no unit was forgotten for this long
TRIM_EVERY_S = 10.0  # ... or this often while they go on being forgotten


class Latency:
    """Recent latencies, receipt of a state to publication of its direction; quantiles when asked."""

    def __init__(self, size: int = 4096) -> None:
        self._samples: collections.deque[float] = collections.deque(maxlen=size)

    def add(self, seconds: float) -> None:
        self._samples.append(seconds)

    def quantiles_ms(self) -> tuple[float | None, float | None]:
        if not self._samples:
            return None, None
        s = sorted(self._samples)
        return 1e3 * s[len(s) // 2], 1e3 * s[min(len(s) - 1, int(0.99 * len(s)))]


class Trim:
    """Give freed memory back to the OS once many units are forgotten (glibc's ``malloc_trim``).

    CPython's allocator and glibc keep freed memory for reuse, so a planner
    that held 10,000 units and forgot them would stay at its peak (measured
    in process: 10,000 units forgotten left 30 MB of 65 MB; trimmed, 14 MB).
    Once ``TRIM_AFTER`` units are forgotten, one ``malloc_trim(0)`` runs when
    the forgetting pauses for ``TRIM_QUIET_S`` (or every ``TRIM_EVERY_S``
    through a long one), on a short-lived thread: ctypes releases the GIL, so
    the loop never waits for it.  Elsewhere than glibc it does nothing.
    """

    def __init__(self) -> None:
        self._pending = 0
        self._last_forget = self._last_trim = -math.inf
        try:
            self._fn: Any = ctypes.CDLL(None).malloc_trim
        except (OSError, AttributeError):
            self._fn = None

    def forgot(self, units: int, now: float) -> None:
        self._pending += units
        self._last_forget = now

    def due(self, now: float) -> None:
        """Called every tick: trim if enough was forgotten and the forgetting paused."""
        if self._fn is None or self._pending < TRIM_AFTER:
            return
        if now - self._last_forget < TRIM_QUIET_S and now - self._last_trim < TRIM_EVERY_S:
            return
        self._pending, self._last_trim = 0, now
        threading.Thread(target=self._fn, args=(0,), name="pfp-trim", daemon=True).start()
