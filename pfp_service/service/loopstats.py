"""The planning loop's own upkeep: its latency figures and handing freed memory back to the OS."""

from __future__ import annotations

import collections
import ctypes
import gc
import json
import math
import threading
import time
from typing import Any

__all__ = ["Latency", "LoopTrace", "Trim"]

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


class LoopTrace:
    """Where the loop thread's time goes: a JSON line a second, appended to ``path`` (config ``loop_trace``).

    Off when ``path`` is None (then nothing is counted; on, a tick costs a few clock reads).
    Per second: ticks, states, the tick's wall time (max, p99), the time in
    draining, ``World.apply``, publishing and the rest, the oldest state's wait
    (receipt to publication) and the collector's pauses by generation
    (``gc.callbacks``), so periodic stalls and queueing show apart.
    """

    def __init__(self, path: str | None, clock: Any) -> None:
        self.on = bool(path)
        self._path = path
        self._clock = clock
        self._reset(clock())
        self._gc_t0 = 0.0
        if self.on:
            gc.callbacks.append(self._gc)

    def close(self) -> None:
        """Stop watching the collector."""
        if self._gc in gc.callbacks:
            gc.callbacks.remove(self._gc)

    def _reset(self, now: float) -> None:
        self._since = now
        self._walls: list[float] = []
        self._parts: collections.defaultdict[str, float] = collections.defaultdict(float)
        self._states = 0
        self._wait_max = 0.0
        self._gc_ms: collections.defaultdict[str, float] = collections.defaultdict(float)
        self._gc_max = 0.0

    def _gc(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._gc_t0 = time.perf_counter()
            return
        ms = 1e3 * (time.perf_counter() - self._gc_t0)
        self._gc_ms[f"gen{info.get('generation')}"] += ms
        self._gc_ms[f"gen{info.get('generation')}_n"] += 1
        self._gc_max = max(self._gc_max, ms)

    def part(self, name: str, seconds: float) -> None:
        self._parts[name] += seconds

    def tick(self, wall: float, states: int, wait: float, now: float) -> None:
        self._walls.append(wall)
        self._states += states
        self._wait_max = max(self._wait_max, wait)
        if now - self._since < 1.0:
            return
        w = sorted(self._walls)
        line = {
            "t": round(now, 3),
            "ticks": len(w),
            "states": self._states,
            "wall_max_ms": round(1e3 * w[-1], 2),
            "wall_p99_ms": round(1e3 * w[min(len(w) - 1, int(0.99 * len(w)))], 2),
            "wall_ms": round(1e3 * sum(w), 1),
            **{f"{k}_ms": round(1e3 * v, 1) for k, v in self._parts.items()},
            "wait_max_ms": round(1e3 * self._wait_max, 2),
            "gc": {k: round(v, 2) for k, v in self._gc_ms.items()},
            "gc_max_ms": round(self._gc_max, 2),
        }
        try:
            with open(self._path or "", "a") as f:
                f.write(json.dumps(line) + "\n")
        except OSError:  # a diagnostic: a file that cannot be written turns it off, never the loop
            self.close()
            self.on = False
        self._reset(now)
