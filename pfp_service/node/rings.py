"""The unit states Zenoh keeps for the planning loop: one ring per key, and a waiter per ring.

The flood of states wakes no Python thread per state: Zenoh holds the latest ``STATE_RING``
of each key in a ring (``zenoh.handlers.RingChannel``), and the loop drains them.  While the
loop idles it arms every ring's waiter, a thread blocked in ``recv`` with the GIL released,
which hands the loop the first state to come and wakes it, once.  The node owns the keys (the
plain key, then this planner's shards as the world says); this module, the rings.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Any

import zenoh

__all__ = ["STATE_RING", "StateRings"]

# unit states Zenoh holds for the loop, per ring (0.4 s of 10,000/s); past it the oldest go first. Each
# sample held keeps its receive buffer alive; under a flood the loop answers fresher states, and a unit
# reports again anyway (figures: docs/operations.md, "Shorter rings")
STATE_RING = 4_096


class StateRings:
    """The rings by name ("plain", "all" or a shard number), each with its waiter thread.

    Args:
        session: where the rings' subscribers are declared.
        lock: the node's lock, held while a waiter hands over the state it took.
        wake: set when a waiter took a state, to wake the loop.
        stop: set when the node stops; the waiters then end.
    """

    def __init__(
        self, session: zenoh.Session, lock: threading.Lock, wake: threading.Event, stop: threading.Event
    ) -> None:
        self._session = session
        self._lock = lock
        self._wake = wake
        self._stop = stop
        # name: (subscriber, its ring, the waiter's arming event)
        self._rings: dict[str, tuple[Any, Any, threading.Event]] = {}
        self._early: list[Any] = []  # states a waiter took while the loop idled, before the rings' rest

    def names(self) -> list[str]:
        return list(self._rings)

    def add(self, name: str, key: str) -> None:
        """Subscribe a ring on ``key``, with its waiter thread (it ends when the ring is removed)."""
        sub = self._session.declare_subscriber(key, zenoh.handlers.RingChannel(STATE_RING))
        ring, armed = sub.handler, threading.Event()  # the handler: recv on the subscriber blocks undeclare
        self._rings[name] = (sub, ring, armed)
        threading.Thread(
            target=self._wait_on, args=(ring, armed), name=f"pfp-ring-{name}", daemon=True
        ).start()

    def remove(self, name: str) -> list[Any]:
        """Undeclare the ring ``name``; returns the states it still held, which still count."""
        sub, ring, armed = self._rings.pop(name)
        left = []
        while (sample := ring.try_recv()) is not None:
            left.append(sample)
        with contextlib.suppress(Exception):  # already gone with the session
            sub.undeclare()
        armed.set()  # its waiter, if parked, finds the ring closed and ends
        return left

    def arm(self) -> None:
        """The loop idles: every waiter may block for its ring's next state."""
        for _sub, _ring, armed in self._rings.values():
            armed.set()

    def drain(self) -> list[Any]:
        """What the rings hold (at most ``STATE_RING`` each), after what a waiter took first."""
        with self._lock:
            samples, self._early = self._early, []  # taken by a waiter before the rest of its ring: first
        for _sub, ring, _armed in self._rings.values():
            n = 0
            while n < STATE_RING:
                sample = ring.try_recv()
                if sample is None:
                    break
                n += 1
                samples.append(sample)
        return samples

    def _wait_on(self, ring: Any, armed: threading.Event) -> None:
        """While the loop idles, block for the ring's next state and wake the loop with it (once per idling)."""
        while not self._stop.is_set():
            armed.wait()
            armed.clear()
            if self._stop.is_set():
                return
            try:
                sample = ring.recv()  # blocks with the GIL released; raises once the ring is undeclared
            except Exception:
                return
            with self._lock:
                self._early.append(sample)
            self._wake.set()
