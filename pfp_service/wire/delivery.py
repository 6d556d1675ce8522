"""Acknowledged writes: a goal or threat put while no planner listens is in force once one starts.

Plain pub/sub has no memory, so a write is delivered in two ways at once:

* the ordinary ``put``/``delete`` on its key, which every observer (the map,
  the TAK bridge) and a planner that is up receive as before; and
* a query on the same key, carrying the same payload, which every planner
  answers (``mumt/{m}/unit/*/goal`` and ``mumt/{m}/threat/*`` are also its
  queryables) with a ``WriteAck`` once the write is committed and applied.

A writer (``Deliverer``) keeps each write until some planner acknowledges it,
and asks again every ``retry_s`` and at once whenever a planner's liveliness
token appears; meanwhile it says it is waiting.  Nothing is replayed after an
acknowledgement: from then on the planner's durable state holds the write.

Every write carries a ``WriteMark`` (the writer's Unix time and session id) as
its Zenoh attachment, on the put and on the query.  Live puts apply in the
order they arrive; a write asked again applies only if newer than every write
its key has seen (``WriteOrder``): a delete is never undone by an older put
asked again by another writer, and the put and the query of one write apply
once.  A put without a mark (a raw ``zenoh`` put) counts as written when received.

Chosen over ``zenoh.ext`` advanced publishers with a cache: those need one
publisher (and its queryable) per key, so a fleet of 10,000 goals would declare
10,000; they tell the writer nothing (it cannot say it is waiting); and a cache
replays its last put to every planner that starts later, after a delete from
another writer too.

Nothing here opens a session; ``Deliverer`` is given one.  ``WriteMark``,
``WriteAck`` and ``WriteOrder`` never touch zenoh.
"""

from __future__ import annotations

import collections
import contextlib
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Literal

import msgspec

from pfp_service.errors import InputError
from pfp_service.wire import keys

__all__ = [
    "Deliverer",
    "Outcome",
    "WriteAck",
    "WriteMark",
    "WriteOrder",
    "decode_ack",
    "decode_mark",
    "describe_key",
]

Outcome = Literal["applied", "duplicate", "superseded", "rejected"]
MARK_MAX_BYTES = 256  # an attachment longer than this is no mark of ours
ORDER_KEYS_MAX = 200_000  # keys whose last write a planner remembers; the oldest go first
Order = tuple[float, str]  # a write's place: (the writer's Unix time, the writer)


class WriteMark(msgspec.Struct, frozen=True, kw_only=True):
    """The attachment of an acknowledged write.

    Attributes:
        t: the writer's Unix time in seconds when it wrote (later wins, per key).
        writer: the writing session's Zenoh id (breaks ties; names the writer).
        delete: the write removes the key's value (a query has no kind of its own).
    """

    t: float
    writer: str = ""
    delete: bool = False

    def order(self) -> tuple[float, str]:
        return (self.t, self.writer)


class WriteAck(msgspec.Struct, frozen=True, kw_only=True):
    """A planner's answer to an acknowledged write.

    ``applied``: in force now; ``duplicate``: this very write was already
    applied (its put came first); ``superseded``: a newer write on the key is
    in force, so this one was dropped; ``rejected``: the payload was refused
    (``reason`` says why) and a ``rejected`` event went out as for a put.
    """

    planner: str
    outcome: Outcome
    session: str = ""
    reason: str = ""


_MARK = msgspec.json.Decoder(WriteMark)
_ACK = msgspec.json.Decoder(WriteAck)


def decode_mark(data: bytes | None) -> WriteMark | None:
    """The ``WriteMark`` of an attachment, or ``None`` (no attachment, or not one of ours)."""
    if not data or len(data) > MARK_MAX_BYTES:
        return None
    try:
        return _MARK.decode(data)
    except (msgspec.ValidationError, msgspec.DecodeError):
        return None


def decode_ack(data: bytes) -> WriteAck:
    """A ``WriteAck`` from a reply payload.

    Raises:
        InputError: at ``$``, when it is not one.
    """
    try:
        return _ACK.decode(data)
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise InputError("$", f"not a write acknowledgement: {exc}") from None


class WriteOrder:
    """What was written last per key, so that a write asked again never undoes a newer one.

    A write that arrives live (its put, while the planner listens) is applied
    in the order it arrives, as any put always was: that order is the truth,
    whatever the writers' clocks say.  A write that is *asked again* (its
    query, after the planner missed its put) is applied only if its mark is
    newer than every write the key has seen; if it is the write last applied
    (its put came first) it is a duplicate.  So a put made while no planner ran
    is in force once one starts, unless a newer write (a delete from another
    writer) came meanwhile.  Marks compare writers' wall clocks only on that
    path: clocks that disagree by more than the time between two conflicting
    writes made while no planner ran can order those two wrongly (use NTP).

    Sans-I/O: the caller passes the wall time at which a mark-less write was received.
    """

    def __init__(self, max_keys: int = ORDER_KEYS_MAX) -> None:
        # key -> (the newest order seen, the order of the write last applied)
        self._last: collections.OrderedDict[str, tuple[Order, Order]] = collections.OrderedDict()
        self._max = max_keys
        self._undo: dict[str, tuple[Order, Order] | None] = {}  # each key's state before this batch

    def admit(self, key: str, mark: WriteMark | None, received_wall_s: float, asked: bool = False) -> Outcome:
        """Whether to apply a write: ``applied``, ``duplicate`` (already applied) or ``superseded``.

        An ``applied`` write is held as this batch's until ``settle``: the store commits it, or the
        order goes back to what it was, so it is never ahead of what is stored.

        Args:
            key: the goal or threat key.
            mark: the write's mark, if it has one (a raw zenoh put has none).
            received_wall_s: when it was received (Unix seconds): the order of a mark-less write.
            asked: it came as a query (asked again), not as a live put.
        """
        outcome, state = _decide(self._last.get(key), _order_of(mark, received_wall_s), asked)
        if state is not None:
            if key not in self._undo:
                self._undo[key] = self._last.get(key)
            self._last[key] = state
            self._last.move_to_end(key)
            if len(self._last) > self._max:
                self._last.popitem(last=False)
        return outcome

    def outcome(
        self, key: str, mark: WriteMark | None, received_wall_s: float, asked: bool = True
    ) -> Outcome:
        """What ``admit`` would say now, changing nothing."""
        return _decide(self._last.get(key), _order_of(mark, received_wall_s), asked)[0]

    def batch_rows(self) -> list[tuple[str, float, str, float, str]]:
        """The keys this batch changed, as the store keeps them: ``(key, newest t, writer, applied t, writer)``."""
        return [(k, *self._last[k][0], *self._last[k][1]) for k in self._undo if k in self._last]

    def settle(self, stored: bool) -> None:
        """End the batch: its admissions stand if the store committed them, else they are undone."""
        if not stored:
            for key, before in self._undo.items():
                if before is None:
                    self._last.pop(key, None)
                else:
                    self._last[key] = before
        self._undo.clear()

    def load(self, rows: Iterable[tuple[str, float, str, float, str]]) -> None:
        """The order a store kept (``batch_rows``' form), at a restart: an older write asked again
        after it stays superseded, so it cannot undo an acknowledged delete."""
        for key, nt, nw, at, aw in rows:
            self._last[key] = ((float(nt), str(nw)), (float(at), str(aw)))
            if len(self._last) > self._max:
                self._last.popitem(last=False)


def _order_of(mark: WriteMark | None, received_wall_s: float) -> Order:
    return mark.order() if mark is not None else (received_wall_s, "")


def _decide(
    last: tuple[Order, Order] | None, order: Order, asked: bool
) -> tuple[Outcome, tuple[Order, Order] | None]:
    """The outcome of a write of ``order`` on a key whose state is ``last``, and the key's new state."""
    if last is None:
        return "applied", (order, order)
    newest, applied = last
    if order == applied:
        return "duplicate", None
    if asked and order <= newest:
        return "superseded", None
    return "applied", (max(newest, order), order)


def describe_key(key: str) -> str:
    """``goal u1``, ``threat t1`` or ``zone z1`` for a goal, threat or zone key; the key itself otherwise."""
    try:
        k = keys.parse(key)
    except InputError:
        return key
    if k.kind is keys.KeyKind.UNIT_GOAL:
        return f"goal {k.id}"
    if k.kind is keys.KeyKind.THREAT:
        return f"threat {k.id}"
    if k.kind is keys.KeyKind.ZONE:
        return f"zone {k.id}"
    return key


@dataclass
class _Pending:
    mark: WriteMark
    payload: bytes | None
    since: float  # monotonic seconds of the write
    told: bool = False  # the writer was told this write is waiting


class Deliverer:
    """Puts and deletes of goals and threats that some planner acknowledges, asked again until one does.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it, after ``close()``).
        mission: the mission's key chunk.
        say: where "waiting for a planner" and "delivered" lines go (``None``: nowhere).
        retry_s: how often pending writes are asked again while no planner answers.
        query_timeout_s: how long one ask waits for a busy planner's acknowledgement.
        wait_note_s: a write still unacknowledged after this long is said to be waiting.
        clock: monotonic seconds; ``wall``: Unix seconds (the marks' time).

    Use ``put(key, payload)`` and ``delete(key)`` on goal and threat keys;
    ``pending()`` lists what no planner has taken yet; ``close()`` stops asking.
    """

    def __init__(
        self,
        session: Any,
        mission: str,
        say: Callable[[str], None] | None = None,
        retry_s: float = 1.0,
        query_timeout_s: float = 2.0,
        wait_note_s: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
        wall: Callable[[], float] = time.time,
    ) -> None:
        import zenoh

        from pfp_service.wire.encoding import zenoh_encoding

        self._zenoh = zenoh
        self.session = session
        self.mission = keys.check_chunk(mission, "--mission")
        self._say = say or (lambda _line: None)
        self._retry_s = retry_s
        self._timeout_s = query_timeout_s
        self._note_s = wait_note_s
        self._clock = clock
        self._wall = wall
        self._enc = zenoh_encoding()
        self._writer = str(session.info.zid())
        self._lock = threading.Lock()
        self._pending: dict[str, _Pending] = {}
        self._kick = threading.Event()
        self._idle = threading.Event()
        self._idle.set()
        self._stop = threading.Event()
        self._last_t = 0.0
        self._planners = session.liveliness().declare_subscriber(
            keys.alive_planners(self.mission), self._on_planner
        )
        self._thread = threading.Thread(target=self._run, name="pfp-deliver", daemon=True)
        self._thread.start()

    # -- the writer's side --------------------------------------------------------
    def put(self, key: str, payload: bytes) -> None:
        """Put ``payload`` on ``key`` now, and keep it until a planner acknowledges it."""
        self._write(key, payload)

    def delete(self, key: str) -> None:
        """Delete ``key`` now, and keep the delete until a planner acknowledges it."""
        self._write(key, None)

    def pending(self) -> list[str]:
        """The keys whose last write no planner has acknowledged yet."""
        with self._lock:
            return list(self._pending)

    def wait_delivered(self, timeout_s: float) -> bool:
        """Block until nothing is pending (True) or ``timeout_s`` passed (False)."""
        return self._idle.wait(timeout_s)

    def close(self) -> None:
        """Stop asking; undeclare.  What is still pending is said once, and given up."""
        self._stop.set()
        self._kick.set()
        self._thread.join(timeout=self._timeout_s + 1.0)
        with contextlib.suppress(Exception):  # already gone with the session
            self._planners.undeclare()
        left = self.pending()
        if left:
            self._say(f"no planner of mission {self.mission!r} took {_names(left)}; given up at exit")

    def __enter__(self) -> Deliverer:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def _write(self, key: str, payload: bytes | None) -> None:
        with self._lock:
            t = max(self._wall(), self._last_t + 1e-6)  # strictly increasing: a writer's order is its own
            self._last_t = t
            mark = WriteMark(t=t, writer=self._writer, delete=payload is None)
            self._pending[key] = _Pending(mark, payload, self._clock())
            self._idle.clear()
        attachment = msgspec.json.encode(mark)
        if payload is None:
            self.session.delete(key, attachment=attachment)
        else:
            self.session.put(key, payload, encoding=self._enc, attachment=attachment)
        self._kick.set()

    def _on_planner(self, sample: Any) -> None:  # a planner came: ask again at once (nothing blocks here)
        if sample.kind == self._zenoh.SampleKind.PUT:
            self._kick.set()

    # -- asking -------------------------------------------------------------------
    def _run(self) -> None:
        probing = False  # no planner answered the last ask: retries ask one write, not thousands
        while not self._stop.is_set():
            kicked = self._kick.wait(self._retry_s)
            self._kick.clear()
            if self._stop.is_set():
                return
            with self._lock:
                batch = [(k, p) for k, p in self._pending.items()]
            if not batch:
                continue
            if probing and not kicked:
                batch = batch[:1]
            try:
                acked = self._query_acks(batch)
            except Exception as exc:  # the session closed under us, or Zenoh refused: try again later
                if self._stop.is_set():
                    return
                self._say(f"acknowledged writes: {exc}")
                acked = 0
            if probing and acked:
                self._kick.set()  # a planner answers now: the rest at once
            probing = acked == 0
            self._note_waiting()

    def _query_acks(self, batch: list[tuple[str, _Pending]]) -> int:
        """Ask a planner to take each write of ``batch``; returns how many some planner answered."""
        z = self._zenoh
        asked = []
        for key, p in batch:
            replies = self.session.get(
                key,
                payload=p.payload,
                encoding=self._enc,
                attachment=msgspec.json.encode(p.mark),
                target=z.QueryTarget.ALL,
                consolidation=z.ConsolidationMode.NONE,
                timeout=self._timeout_s,
            )
            asked.append((key, p, replies))
        delivered: list[tuple[str, _Pending, WriteAck]] = []
        for key, p, replies in asked:
            ack = None
            for reply in replies:
                if reply.ok is None:
                    continue
                with contextlib.suppress(InputError):
                    ack = decode_ack(reply.ok.payload.to_bytes())
            if ack is not None:
                delivered.append((key, p, ack))
        done: list[tuple[str, _Pending, WriteAck]] = []
        with self._lock:
            for key, p, ack in delivered:
                if self._pending.get(key) is p:  # a newer write on the key is still to be asked
                    del self._pending[key]
                    done.append((key, p, ack))
            if not self._pending:
                self._idle.set()
        for key, p, ack in done:
            if ack.outcome == "rejected":
                self._say(f"planner {ack.planner} rejected {describe_key(key)}: {ack.reason}")
            elif ack.outcome == "superseded":
                self._say(f"{describe_key(key)}: a newer write is in force at planner {ack.planner}")
            elif p.told:
                waited = self._clock() - p.since
                self._say(f"{describe_key(key)} taken by planner {ack.planner} after {waited:.1f} s")
        return len(delivered)

    def _note_waiting(self) -> None:
        now = self._clock()
        with self._lock:
            new = [k for k, p in self._pending.items() if not p.told and now - p.since >= self._note_s]
            for k in new:
                self._pending[k].told = True
            total = len(self._pending)
        if new:
            self._say(
                f"waiting for a planner of mission {self.mission!r} to take {_names(new)}"
                f" ({total} pending; asked again every {self._retry_s:g} s and when one starts)"
            )


def _names(key_list: list[str], limit: int = 5) -> str:
    shown = [describe_key(k) for k in key_list[:limit]]
    more = len(key_list) - limit
    return ", ".join(shown) + (f" and {more} more" if more > 0 else "")
