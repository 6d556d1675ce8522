"""The planning loop's own upkeep: its latency figures and handing freed memory back to the OS."""

from __future__ import annotations

import collections
import ctypes
import gc
import json
import math
import os
import threading
import time
from typing import Any

__all__ = ["Latency", "LoopTrace", "Trim", "demote_native_threads"]

TRIM_AFTER = 256  # units forgotten before freed memory is handed back to the OS
TRIM_QUIET_S = 1.0  # ... once no unit was forgotten for this long
TRIM_EVERY_S = 10.0
SLOW_PUT_S = 200e-6  # a direction's put this long waited for something (a put costs ~10 us of CPU)  # ... or this often while they go on being forgotten


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

    def waiting(self) -> bool:
        """Whether a trim waits for the forgetting to pause: the loop comes back for ``due``."""
        return self._fn is not None and self._pending >= TRIM_AFTER

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
        self._cpu = time.thread_time()
        self._nonvol = 0
        self._ticks_of: dict[str, int] = {}  # thread name -> its CPU clock ticks at the last line
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
        self._puts = self._puts_slow = 0
        self._put_max = self._put_slow_s = 0.0

    def _gc(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._gc_t0 = time.perf_counter()
            return
        ms = 1e3 * (time.perf_counter() - self._gc_t0)
        self._gc_ms[f"gen{info.get('generation')}"] += ms
        self._gc_ms[f"gen{info.get('generation')}_n"] += 1
        self._gc_max = max(self._gc_max, ms)

    def _threads(self) -> dict[str, float]:
        """CPU milliseconds of each busy thread of this process since the last line (Linux; else empty).

        Python's threads by their names, Zenoh's by the kernel's: a busy thread
        beside the loop takes the GIL each time the loop lets it go (a put, a
        sleep), so its time shows as the loop's wall time without CPU.
        """
        names = {t.native_id: t.name for t in threading.enumerate()}
        now: dict[str, int] = {}
        try:
            for tid in os.listdir("/proc/self/task"):
                with open(f"/proc/self/task/{tid}/stat") as f:
                    stat = f.read()
                comm, rest = (
                    stat[stat.index("(") + 1 : stat.rindex(")")],
                    stat[stat.rindex(")") + 2 :].split(),
                )
                name = names.get(int(tid)) or comm
                now[name] = now.get(name, 0) + int(rest[11]) + int(rest[12])  # utime + stime
        except (OSError, ValueError, IndexError):
            return {}
        hz = os.sysconf("SC_CLK_TCK")
        busy = {k: 1e3 * (v - self._ticks_of.get(k, 0)) / hz for k, v in now.items()}
        self._ticks_of = now
        return {k: round(v, 1) for k, v in sorted(busy.items(), key=lambda kv: -kv[1]) if v > 0}

    def _preempted(self) -> int | None:
        """The loop thread's involuntary context switches since the last line (Linux; else None)."""
        try:
            with open(f"/proc/self/task/{threading.get_native_id()}/status") as f:
                n = next(int(ln.split()[1]) for ln in f if ln.startswith("nonvoluntary_ctxt_switches"))
        except (OSError, StopIteration, ValueError):
            return None
        got, self._nonvol = n - self._nonvol, n
        return got

    def put(self, seconds: float) -> None:
        """One direction's ``session.put`` alone: the slow ones counted (``SLOW_PUT_S``), the slowest kept."""
        self._puts += 1
        self._put_max = max(self._put_max, seconds)
        if seconds > SLOW_PUT_S:
            self._puts_slow += 1
            self._put_slow_s += seconds

    def part(self, name: str, seconds: float) -> None:
        self._parts[name] += seconds

    def tick(self, wall: float, states: int, wait: float, now: float) -> None:
        self._walls.append(wall)
        self._states += states
        self._wait_max = max(self._wait_max, wait)
        if now - self._since < 1.0:
            return
        w = sorted(self._walls)
        cpu = time.thread_time()
        line: dict[str, Any] = {
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
            "puts": self._puts,
            "puts_slow": self._puts_slow,
            "puts_slow_ms": round(1e3 * self._put_slow_s, 1),
            "put_max_ms": round(1e3 * self._put_max, 2),
            "loop_preempted": self._preempted(),  # the loop thread's involuntary context switches
            "loop_cpu_ms": round(1e3 * (cpu - self._cpu), 1),  # against wall_ms: the rest waited
            "threads_cpu_ms": self._threads(),
        }
        self._cpu = cpu
        try:
            with open(self._path or "", "a") as f:
                f.write(json.dumps(line) + "\n")
        except OSError:  # a diagnostic: a file that cannot be written turns it off, never the loop
            self.close()
            self.on = False
        self._reset(now)


def demote_native_threads() -> int:
    """Put this process's non-Python threads (Zenoh's rx, tx, runtime) under ``SCHED_BATCH``; how many moved.

    Each direction's put wakes Zenoh's tx thread and each arriving state its
    rx thread; on a 2-core machine the woken thread preempted the planning loop
    mid-tick (measured at 5,000 states/s: ~2,000-2,600 involuntary switches of
    the loop thread a second, 10-12 % of its puts taking over 200 us, the
    tick's wall time 1.7x its CPU).  ``SCHED_BATCH`` keeps their share of the
    CPU but lets them no longer preempt on wake-up: they run on the other core
    or once the tick sleeps, so a tick's directions go out together.  Allowed
    without privileges (priority 0); elsewhere than Linux, nothing.
    """
    batch = getattr(os, "SCHED_BATCH", None)
    if batch is None or not hasattr(os, "sched_setscheduler"):
        return 0
    python = {t.native_id for t in threading.enumerate()}
    moved = 0
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return 0
    for tid in tids:
        if tid in python:
            continue
        try:
            if os.sched_getscheduler(tid) != batch:
                os.sched_setscheduler(tid, batch, os.sched_param(0))
                moved += 1
        except OSError:  # gone meanwhile, or not permitted: it keeps the default policy
            continue
    return moved
