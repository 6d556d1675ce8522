"""The world's write kinds (goals, threats, zones, teams: ``world.kinds.WRITES``) on their way to it:
plain puts and acknowledged-write queries.

Each write kind is one subscriber and one queryable (``declare``, which the node calls for each
kind of mode ``write``), both handled by the one generic handler (``_maker``: the key's id, then
the kind's put or remove).  Callbacks decode a write into its ``Input`` (or an ``InputRejected`` naming
why) and queue it, bounded (``WRITES_MAX``; past it a put is counted lost and
a query dropped, its writer asks again).  The planning loop takes a slice per
tick (``take``), orders it (``admit``: ``wire.delivery.WriteOrder`` says
which writes apply, which are duplicates of a put already seen and which an
older write asked again would wrongly undo) and, once the batch is committed
and applied, answers each query with a ``WriteAck`` (``acknowledge``).  No
callback replies: the loop does.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec
import zenoh

from pfp_service.errors import InputError
from pfp_service.node.config import ServeConfig
from pfp_service.wire import keys
from pfp_service.wire.delivery import WriteAck, WriteMark, WriteOrder, decode_mark
from pfp_service.world.events import Input, InputRejected
from pfp_service.world.kinds import Kind

__all__ = ["WRITES_MAX", "Write", "Writes"]

WRITES_MAX = 100_000  # goal, threat and zone writes waiting (puts and queries); more are shed
_JSON = zenoh.Encoding.APPLICATION_JSON


class Write:
    """A goal, threat or zone write from a put (``query`` None) or an acknowledged-write query."""

    __slots__ = ("input", "key", "mark", "query", "received")

    def __init__(self, key: str, mark: WriteMark | None, inp: Input, received: float, query: Any) -> None:
        self.key, self.mark, self.input, self.received, self.query = key, mark, inp, received, query


class Writes:
    """The writes waiting for the loop, under the node's ``lock``.

    Args:
        cfg: the service configuration (bounds and origin to decode with, the planner's id).
        zid: this planner's Zenoh session id, named in each ``WriteAck``.
        lock: the node's lock (the callbacks' threads and the loop's share it).
        wake: wakes the planning loop.
        refused: counts a write shed here (``Intake.refused``, under ``lock``).
    """

    def __init__(
        self,
        cfg: ServeConfig,
        zid: str,
        lock: threading.Lock,
        wake: Callable[[], None],
        refused: Callable[[], None],
    ) -> None:
        self.cfg = cfg
        self.zid = zid
        self._lock = lock
        self._wake = wake
        self._refused = refused
        self._waiting: collections.deque[Write] = collections.deque()
        self.order = WriteOrder()  # the node settles it once the store has committed (or refused) a batch

    def declare(self, s: zenoh.Session, mission: str, kind: Kind) -> list[Any]:
        """Subscribe to one write kind's keys, and serve them as acknowledged-write queryables (wire.delivery:
        the same writes, asked until a planner answers)."""
        make, key_expr = self._maker(kind, mission), kind.wildcard(mission)
        return [
            s.declare_subscriber(key_expr, functools.partial(self._on_sample, make=make)),
            s.declare_queryable(key_expr, functools.partial(self._on_query, make=make)),
        ]

    # -- the loop's side (under the lock for take and waiting) ------------------------------
    def take(self, most: int) -> collections.deque[Write]:
        """This tick's writes, the oldest first, at most ``most`` (call under the lock)."""
        if len(self._waiting) <= most:
            got, self._waiting = self._waiting, collections.deque()
            return got
        return collections.deque(self._waiting.popleft() for _ in range(most))

    def waiting(self) -> bool:
        """Writes are left for the next tick (call under the lock)."""
        return bool(self._waiting)

    def admit(
        self, writes: collections.deque[Write], inbox: collections.deque[Input]
    ) -> list[tuple[Write, str]]:
        """The writes to apply join ``inbox`` (``WriteOrder``); the outcome of each write.

        Live puts apply in the order they arrive.  A write's put and its query
        carry one mark: the second is a duplicate.  An older write asked again
        (a put while no planner ran, then a delete from another writer) is
        superseded, never applied over the newer one.
        """
        acks: list[tuple[Write, str]] = []
        self.order.settle(True)  # a batch of its own: nothing held from before
        for w in writes:
            if isinstance(w.input, InputRejected):
                outcome = "rejected"  # never ordered: a bad write supersedes nothing
                if w.query is None:
                    inbox.append(w.input)  # the rejected event comes from the put; the writer's ask hears why
            else:
                outcome = self.order.admit(w.key, w.mark, w.received, asked=w.query is not None)
                if outcome == "applied":
                    inbox.append(w.input)
            if w.query is not None:
                acks.append((w, outcome))
        return acks

    def acknowledge(self, acks: list[tuple[Write, str]], refused: str | None) -> None:
        """Answer each acknowledged-write query, once its write is committed and applied (or refused).

        ``refused``: why the store refused this batch.  Then only what the store already held is
        acknowledged (a duplicate of a stored write, or one a stored write supersedes), against the
        order as it was before the batch; every other write is ``rejected``, naming the cause.
        """
        if not acks:
            return
        for w, outcome in acks:
            reason = ""
            if isinstance(w.input, InputRejected):
                reason = f"{w.input.error.path}: {w.input.error.reason}"
            elif refused is not None:
                outcome = self.order.outcome(w.key, w.mark, w.received, asked=True)
                if outcome == "applied":  # not stored: an explicit refusal, never "duplicate"
                    outcome, reason = "rejected", refused
            ack = WriteAck(planner=self.cfg.planner_id, session=self.zid, outcome=outcome, reason=reason)  # type: ignore[arg-type]
            with contextlib.suppress(Exception):  # the writer gave up waiting: nothing to answer
                w.query.reply(w.key, msgspec.json.encode(ack), encoding=_JSON)
            w.query.drop()

    # -- callbacks: decode and enqueue, nothing more ----------------------------------------
    def _push(self, write: Write) -> None:
        with self._lock:
            if len(self._waiting) >= WRITES_MAX:  # shed: a writer asks again, a put is counted lost
                self._refused()
                if write.query is not None:
                    write.query.drop()
                return
            self._waiting.append(write)
        self._wake()

    def _on_sample(self, sample: zenoh.Sample, make: Callable[[str, bool, bytes], Input]) -> None:
        key = str(sample.key_expr)
        att = sample.attachment
        mark = decode_mark(att.to_bytes() if att is not None else None)
        inp = make(key, sample.kind == zenoh.SampleKind.DELETE, sample.payload.to_bytes())
        self._push(Write(key, mark, inp, time.time(), None))

    def _on_query(self, query: zenoh.Query, make: Callable[[str, bool, bytes], Input]) -> None:
        key = str(query.key_expr)
        att = query.attachment
        mark = decode_mark(att.to_bytes() if att is not None else None)
        if mark is None:  # not a write: a plain get on a goal or threat key has nothing to learn here
            query.drop()  # type: ignore[no-untyped-call]  # zenoh stub
            return
        body = query.payload
        inp = make(key, mark.delete, body.to_bytes() if body is not None else b"")
        self._push(Write(key, mark, inp, time.time(), query))

    def _maker(self, kind: Kind, mission: str) -> Callable[[str, bool, bytes], Input]:
        ids = keys.KeyOf(kind.key, mission)
        bounds, origin = self.cfg.bounds, self.cfg.origin

        def make(key: str, delete: bool, payload: bytes) -> Input:
            """The write's input, or its refusal: the key's kind named once the key itself parsed."""
            try:
                ident = ids.id(key)
            except InputError as err:
                return InputRejected(key, err)
            try:
                return kind.make(ident, delete, payload, bounds, origin)
            except InputError as err:
                return InputRejected(key, err, kind.key)

        return make
