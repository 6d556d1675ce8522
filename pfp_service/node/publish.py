"""What the planner puts on the wire, and how: directions batched and droppable, events stamped and logged.

The node's loop decides what goes out (the world's outputs); this is the one place that puts it,
counting every message (``PlannerStatus.msgs_out``).
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable

import msgspec
import zenoh

from pfp_service.node.log import get_logger
from pfp_service.node.loopstats import LoopTrace
from pfp_service.wire import ConflictEvent, Direction, Event, RejectedEvent, encode, keys

__all__ = ["EVENT_LOG_LINES", "Publisher"]

log = get_logger("node")  # the planner's own lines, as before they had a module
_JSON = zenoh.Encoding.APPLICATION_JSON
EVENT_LOG_LINES = 20  # log lines per kind of event per tick; the rest are counted in one line


class Publisher:
    """Puts on ``session`` for ``mission``, counting each in ``counters["msgs_out"]``."""

    def __init__(self, session: zenoh.Session, mission: str, counters: dict[str, int]) -> None:
        self.session = session
        self._mission = mission
        self.counters = counters

    def put(self, key: str | zenoh.KeyExpr, payload: bytes, direction: bool = False) -> None:
        if direction:
            # not express: Zenoh batches a tick's directions, a fifth of the loop's cost a put, and
            # express bursts overflowed the transmit queue under DROP (figures: docs/operations.md)
            self.session.put(
                key,
                payload,
                encoding=_JSON,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.INTERACTIVE_HIGH,
            )
        else:
            self.session.put(key, payload, encoding=_JSON)
        self.counters["msgs_out"] += 1

    def directions(
        self,
        directions: list[Direction],
        key_of: Callable[[str], zenoh.KeyExpr],
        trace: LoopTrace,
        clock: Callable[[], float],
    ) -> None:
        """Put each of ``directions`` on its unit's key (``key_of``), each put timed on ``clock`` when ``trace`` is
        on: a put that waits (Zenoh's queue, the GIL) shows apart from its CPU."""
        if trace.on:
            for d in directions:
                key, body = key_of(d.unit), encode(d)
                t = clock()
                self.put(key, body, direction=True)
                trace.put(clock() - t)
        else:
            for d in directions:
                self.put(key_of(d.unit), encode(d), direction=True)

    def event(self, ev: Event, logged: collections.Counter[str]) -> None:
        """Publish ``ev`` with the wall-clock time, and log it (``EVENT_LOG_LINES`` a kind in ``logged``)."""
        ev = msgspec.structs.replace(ev, t=time.time())  # wall-clock time; planning never reads it
        kind = ev.__struct_config__.tag
        self.put(keys.event(self._mission, str(kind)), encode(ev))
        logged[str(kind)] += 1
        if logged[str(kind)] > EVENT_LOG_LINES:
            return
        fields = {k: v for k, v in msgspec.structs.asdict(ev).items() if k not in ("t", "planner")}
        if isinstance(ev, RejectedEvent):
            log.warning("rejected input", extra={"fields": fields})
        elif isinstance(ev, ConflictEvent):  # two planners guiding one unit: a vehicle overshot its goal
            log.warning("conflict: a twin planner", extra={"fields": fields})
        else:
            log.info(str(kind), extra={"fields": fields})
