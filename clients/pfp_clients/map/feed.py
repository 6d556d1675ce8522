"""The map's Zenoh side: subscriptions whose callbacks decode and enqueue, and the blocking queries and puts.

Callbacks decode each sample into a ``model`` input and enqueue it, nothing
more (an undecodable sample is dropped: the planner publishes its own
rejections).  Positions and directions come ten times a second per unit and
only the newest matters to a page drawn five times a second, so those two
kinds go to a mailbox keeping the latest per unit; everything else keeps its
order in a queue.  ``drain()`` takes both at once.  The ``ask_*`` methods and
``send`` block: call them off the event loop, never from a callback.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pfp_clients.map.samples import (
    AliveSeen,
    DirectionSeen,
    EventSeen,
    GoalSeen,
    Input,
    StateSeen,
    StatusSeen,
    TeamSeen,
    ThreatSeen,
    WorldSeen,
    ZoneSeen,
)
from pfp_service.core.plan import PlanResult
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import (
    decode_direction,
    decode_error_reply,
    decode_event,
    decode_goal,
    decode_planner_status,
    decode_threat,
    decode_unit_state,
    decode_world_snapshot,
    encode,
    keys,
)
from pfp_service.wire.encoding import zenoh_encoding
from pfp_service.wire.messages import decode_team, decode_zone
from pfp_service.world.translate import decode_plan_result

__all__ = ["Feed", "PreviewError"]

log = logging.getLogger("pfp.map")


@dataclass(frozen=True)
class PreviewError:
    """Why there is no preview: the planner's error reply (with its field), or no answer at all."""

    error: str
    field: str = "$"


class Feed:
    """One mission's samples in, and the map's queries and edits out, on an open session.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        mission: the mission's key chunk.
        query_timeout_s: how long a status, world or preview query waits.
    """

    def __init__(
        self, session: Any, mission: str, query_timeout_s: float = 2.0, origin: Origin | None = None
    ) -> None:
        self.session = session
        self.origin = origin  # a zone's lat/lon vertices become metres from it
        self.mission = keys.check_chunk(mission, "--mission")
        self.query_timeout_s = query_timeout_s
        self._inbox: queue.SimpleQueue[Input] = queue.SimpleQueue()
        self._latest: dict[tuple[type, str], Input] = {}
        self._latest_lock = threading.Lock()
        self._declared: list[Any] = []
        self._writes: Any = None  # a wire.delivery.Deliverer once declared
        self.samples_in = 0

    # -- in: decode and enqueue, nothing more -------------------------------------------
    def _enqueue(self, make: Callable[[Any], Input | None]) -> Callable[[Any], None]:
        def callback(sample: Any) -> None:
            try:
                item = make(sample)
            except InputError:
                return  # not ours to judge: the planner publishes its own rejections
            except Exception:  # a callback must never die; say so and carry on
                log.exception("map: cannot read a sample on %s", sample.key_expr)
                return
            if item is None:
                return
            self.samples_in += 1
            if isinstance(item, (StateSeen, DirectionSeen)):
                with self._latest_lock:
                    self._latest[(type(item), item.unit)] = item
            else:
                self._inbox.put(item)

        return callback

    def declare(self) -> None:
        """Subscribe to the mission: states, directions, goals, threats, events and liveliness."""
        import zenoh

        m = self.mission
        s = self.session

        def chunk(sample: Any) -> str:
            return keys.parse(str(sample.key_expr)).id

        def is_delete(sample: Any) -> bool:
            return bool(sample.kind == zenoh.SampleKind.DELETE)

        def on_state(smp: Any) -> Input:
            return StateSeen(chunk(smp), decode_unit_state(smp.payload.to_bytes()))

        def on_direction(smp: Any) -> Input:
            return DirectionSeen(chunk(smp), decode_direction(smp.payload.to_bytes()))

        def on_goal(smp: Any) -> Input:
            return GoalSeen(chunk(smp), None if is_delete(smp) else decode_goal(smp.payload.to_bytes()))

        def on_threat(smp: Any) -> Input:
            return ThreatSeen(chunk(smp), None if is_delete(smp) else decode_threat(smp.payload.to_bytes()))

        def on_zone(smp: Any) -> Input:  # lat/lon vertices need the origin (the map's, if it has one)
            return ZoneSeen(
                chunk(smp), None if is_delete(smp) else decode_zone(smp.payload.to_bytes(), None, self.origin)
            )

        def on_team(smp: Any) -> Input:
            return TeamSeen(chunk(smp), None if is_delete(smp) else decode_team(smp.payload.to_bytes()))

        def on_event(smp: Any) -> Input:
            return EventSeen(decode_event(smp.payload.to_bytes()))

        def on_alive(smp: Any) -> Input:
            return AliveSeen(chunk(smp), not is_delete(smp))

        self._declared = [
            s.declare_subscriber(keys.unit_states_any(m), self._enqueue(on_state)),
            s.declare_subscriber(keys.unit_directions(m), self._enqueue(on_direction)),
            s.declare_subscriber(keys.goals(m), self._enqueue(on_goal)),
            s.declare_subscriber(keys.threats(m), self._enqueue(on_threat)),
            s.declare_subscriber(keys.zones(m), self._enqueue(on_zone)),
            s.declare_subscriber(keys.teams(m), self._enqueue(on_team)),
            s.declare_subscriber(keys.events(m), self._enqueue(on_event)),
            s.liveliness().declare_subscriber(keys.alive_units(m), self._enqueue(on_alive), history=True),
        ]
        from pfp_service.wire.delivery import Deliverer

        # edits are acknowledged writes: made while no planner runs, they are in force once one starts
        if self._writes is None:
            self._writes = Deliverer(s, m, lambda line: log.warning("map: %s", line))

    def undeclare(self) -> None:
        """Withdraw every subscriber and stop asking planners to take edits (before the session closes)."""
        if self._writes is not None:
            self._writes.close()
            self._writes = None
        for d in self._declared:
            with contextlib.suppress(Exception):  # the session may already be closing
                d.undeclare()
        self._declared = []

    # -- blocking Zenoh calls, run on the executor ----------------------------------
    def _query(self, selector: str) -> list[Any]:
        return list(self.session.get(selector, timeout=self.query_timeout_s))

    def ask_world(self) -> int:
        """Ask every planner what it holds, and enqueue the answers; returns how many answered."""
        n = 0
        for reply in self._query(keys.worlds(self.mission)):
            if reply.ok is None:
                continue
            try:
                self._inbox.put(WorldSeen(decode_world_snapshot(reply.ok.payload.to_bytes())))
                n += 1
            except InputError as exc:
                log.warning("map: unreadable world reply: %s", exc)
        return n

    def ask_status(self) -> None:
        """Ask every planner's status, and enqueue the answers."""
        for reply in self._query(keys.planner_statuses(self.mission)):
            if reply.ok is None:
                continue
            with contextlib.suppress(InputError):
                self._inbox.put(StatusSeen(decode_planner_status(reply.ok.payload.to_bytes())))

    def ask_preview(self, unit: str) -> PlanResult | PreviewError:
        """The planner's preview of ``unit`` (its live state to its live goal), or why there is none.

        Raises:
            InputError: ``unit`` is not a key chunk, or the reply is not a ``PlanResult``.
        """
        replies = self._query(keys.preview(self.mission, unit))
        for reply in replies:
            if reply.ok is not None:
                return decode_plan_result(reply.ok.payload.to_bytes())
        for reply in replies:
            if reply.err is not None:
                data = reply.err.payload.to_bytes()
                try:
                    err = decode_error_reply(data)
                except InputError:
                    return PreviewError(data.decode(errors="replace") or "no answer")
                return PreviewError(err.error, err.field)
        return PreviewError("no planner of this mission answered")

    def send(self, key: str, msg: Any | None) -> None:
        """Put ``msg`` on ``key`` as every client does, or delete ``key`` when ``msg`` is None.

        A goal or threat edit is an acknowledged write (``wire.delivery``) once declared.
        """
        if self._writes is not None:
            if msg is None:
                self._writes.delete(key)
            else:
                self._writes.put(key, encode(msg))
        elif msg is None:
            self.session.delete(key)
        else:
            self.session.put(key, encode(msg), encoding=zenoh_encoding())

    # -- the pump's side -------------------------------------------------------------
    # -- the pump --------------------------------------------------------------------
    def drain(self) -> list[Input]:
        """Everything queued, then the newest state and direction of each unit.

        Queued inputs go first: a unit's report after a planner's stale event revives it, and
        the planner says stale only after a silence, so no report precedes it in one tick.
        """
        batch: list[Input] = []
        while True:
            try:
                batch.append(self._inbox.get_nowait())
            except queue.Empty:
                break
        with self._latest_lock:
            latest, self._latest = self._latest, {}
        batch.extend(latest.values())
        return batch

    def backlog(self) -> int:
        """Inputs waiting for the next ``drain()``."""
        return self._inbox.qsize() + len(self._latest)
