"""The world's limits on what it says: rejections rate-limited per kind of key, faults logged once a minute per key.

Every rejection and every fault is counted; what is held back is counted too,
and said with the next one that goes out (``suppressed``, ``held``).  Memory
is bounded: one window per kind of key, and at most ``FAULT_KEYS_MAX`` keys'
fault windows, past which one window (``ANY_KEY``) stands for the rest.
Pure values: ``now`` is a parameter.
"""

from __future__ import annotations

import math

from pfp_service.wire import keys

__all__ = ["ANY_KEY", "FAULT_KEYS_MAX", "FAULT_LOG_S", "REJECTS_PER_S", "Limits"]

REJECTS_PER_S = 5  # rejected events per second per kind of key; the rest are counted in the next
FAULT_LOG_S = 60.0  # a fault is logged once per key in this long; the rest are counted in the next
FAULT_KEYS_MAX = 1024  # keys whose fault-log window is remembered; past it, one line for all the rest
ANY_KEY = "*"  # the fault-log key of faults on keys past FAULT_KEYS_MAX


class Limits:
    """The counters of refusals and the windows that pace what is said of them."""

    def __init__(self) -> None:
        self.overload = 0  # inputs refused at a limit (the world's and the node's queues)
        self.rejected = 0
        self.faults = 0  # inputs, timers and unit steps that failed inside the world (bulkheads)
        self._reject_window: dict[str, tuple[float, int, int]] = {}  # kind -> (window start, sent, held)
        self._fault_log: dict[str, tuple[float, int]] = {}  # key -> (when last logged, held since)

    def counts(self) -> dict[str, int]:
        return {"overload": self.overload, "rejected": self.rejected, "faults": self.faults}

    def reject(self, kind: keys.KeyKind | None, now: float) -> int | None:
        """Count a rejection on a key of ``kind``: its window is its kind's (``unit_state``, ``threat``, ...;
        ``None``, a key outside the layout: ``unknown``).  The caller knows the kind: no key is parsed here.

        Returns:
            ``None`` if its event is held back (``REJECTS_PER_S`` already went
            out this second), else how many were held back before it.
        """
        self.rejected += 1
        window = "unknown" if kind is None else kind.value
        start, sent, held = self._reject_window.get(window, (now, 0, 0))
        if now - start >= 1.0:
            start, sent = now, 0
        if sent >= REJECTS_PER_S:
            self._reject_window[window] = (start, sent, held + 1)
            return None
        self._reject_window[window] = (start, sent + 1, 0)
        return held

    def fault(self, key: str, now: float) -> tuple[str, int] | None:
        """Count a fault on ``key``.

        Returns:
            ``None`` if it is not to be logged (one on this key was logged less
            than ``FAULT_LOG_S`` ago), else the key to log it under (``ANY_KEY``
            once ``FAULT_KEYS_MAX`` keys are remembered) and how many were held
            back since the last line.
        """
        self.faults += 1
        log = self._fault_log
        if key not in log and len(log) >= FAULT_KEYS_MAX:
            for old, (when, _held) in list(log.items()):
                if now - when >= FAULT_LOG_S:
                    del log[old]
            if len(log) >= FAULT_KEYS_MAX:
                key = ANY_KEY
        when, held = log.get(key, (-math.inf, 0))
        if now - when < FAULT_LOG_S:
            log[key] = (when, held + 1)
            return None
        log[key] = (now, 0)
        return key, held
