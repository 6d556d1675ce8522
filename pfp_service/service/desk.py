"""The preview desk: previews answered by worker processes, each exactly once and within its deadline.

The loop hands each preview query here with the unit's detached view
(``World.view``).  A worker process computes it with ``preview()`` within
what is left of the query's budget; the loop calls ``expire(now)`` every
tick and answers ``expired`` any query still unanswered past its deadline,
even while its worker is stuck in it.  Whichever comes first answers; the
other is a no-op.  Replies over the payload limit are decimated
(``fit_reply``).

Why processes: a preview is a Python stepping loop, and a thread running it
shares the GIL with the planning loop (measured: the live stream's p99 rose
from 18 ms to 185 ms under a 60-query storm with two preview threads, on a
loaded machine).  In its own process it shares nothing.  The threats in
force are pickled once per field and cached on both sides, so a preview
ships only the unit's stepper copy and its request.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import heapq
import pickle
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import zenoh

from pfp_service import geojson
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.service.events import GoalSet, StateReported, ThreatPut, UnitView, WorldSettings
from pfp_service.service.log import get_logger
from pfp_service.service.preview import fit_reply, preview
from pfp_service.service.workers import spawn_pool, stop_pool
from pfp_service.wire import ErrorReply, Goal, ThreatUpdate, UnitState, decode_preview_request, encode
from pfp_service.wire.messages import Bounds

__all__ = ["EXPIRY_GRACE_S", "PreviewDesk", "warm_up"]

log = get_logger("previews")
_JSON = zenoh.Encoding.APPLICATION_JSON
EXPIRY_GRACE_S = 0.05  # a preview still computing this long past its deadline is answered "expired"


class _Answer:
    """One preview query, answered exactly once."""

    def __init__(self, query: zenoh.Query, deadline: float) -> None:
        self.query = query
        self.deadline = deadline
        self.done = False
        self._lock = threading.Lock()

    def _claim(self) -> bool:
        with self._lock:
            if self.done:
                return False
            self.done = True
            return True

    def reply(self, key: str, body: bytes) -> None:
        if self._claim():
            with contextlib.suppress(Exception):  # the querier may be gone
                self.query.reply(key, body, encoding=_JSON)
                self.query.drop()

    def error(self, err: ErrorReply) -> None:
        if self._claim():
            with contextlib.suppress(Exception):
                self.query.reply_err(encode(err), encoding=_JSON)
                self.query.drop()


class PreviewDesk:
    """Previews on ``workers`` threads, at most ``queue`` in flight, each within ``budget_s``.

    Args:
        clock: the node's monotonic clock (deadlines are on it).
        bounds, origin: the mission's, for decoding requests.
    """

    def __init__(
        self,
        workers: int,
        queue: int,
        budget_s: float,
        max_iter: int,
        clock: Callable[[], float],
        bounds: Bounds | None,
        origin: Origin | None,
    ) -> None:
        self._workers = workers
        self._pool = self._new_pool()
        self._threats_key: tuple[Any, ...] | None = (
            None  # the field last shipped: (its tuple, version, bytes)
        )
        self._version = 0
        self._queue = queue
        self._budget_s = budget_s
        self._max_iter = max_iter
        self._clock = clock
        self._bounds = bounds
        self._origin = origin
        self._pending: dict[int, _Answer] = {}
        self._deadlines: list[tuple[float, int, _Answer]] = []

    def _new_pool(self) -> ProcessPoolExecutor:
        pool, self._started = spawn_pool(self._workers)  # started (and warmed) now, not at the first preview
        return pool

    def wait_ready(self, timeout_s: float = 120.0) -> None:
        """Block until every worker has loaded the kernels (the node calls it before serving)."""
        for f in self._started:
            f.result(timeout=timeout_s)

    def shutdown(self) -> None:
        """Stop at once: a worker still inside a preview is terminated, not waited for."""
        stop_pool(self._pool)

    def _threats_blob(self, threats: tuple[Any, ...]) -> tuple[int, bytes]:
        if self._threats_key is None or self._threats_key[0] is not threats:
            self._version += 1
            self._threats_key = (
                threats,
                self._version,
                pickle.dumps(threats, protocol=pickle.HIGHEST_PROTOCOL),
            )
        return self._threats_key[1], self._threats_key[2]

    def refuse(self, query: zenoh.Query, err: ErrorReply) -> None:
        """Answer a query the loop will not compute (a bad key, say)."""
        _Answer(query, 0.0).error(err)

    def submit(self, query: zenoh.Query, key: str, view: UnitView, received: float) -> None:
        """Queue one preview; busy (more than ``queue`` in flight) is answered at once."""
        if len(self._pending) >= self._queue:
            self.refuse(query, ErrorReply(error="planner busy: too many previews queued"))
            return
        answer = _Answer(query, received + self._budget_s)
        self._pending[id(answer)] = answer
        heapq.heappush(self._deadlines, (answer.deadline, id(answer), answer))
        payload = query.payload.to_bytes() if query.payload is not None else b""
        version, blob = self._threats_blob(view.threats)
        job = (dataclasses.replace(view, threats=()), version, blob, payload, self._bounds, self._origin)
        try:
            future = self._pool.submit(_compute, job, answer.deadline - self._clock(), self._max_iter)
        except BrokenProcessPool:  # a worker died: a fresh pool, and this query is answered as an error
            log.error("preview workers died; starting new ones")
            self._pool = self._new_pool()
            answer.error(ErrorReply(error="internal error while previewing", field="$"))
            return
        future.add_done_callback(functools.partial(self._done, answer=answer, key=key))

    def _done(self, future: Future[tuple[str, bytes]], *, answer: _Answer, key: str) -> None:
        try:
            kind, body = future.result()
        except Exception:
            log.exception("preview failed", extra={"fields": {"key": key}})
            answer.error(ErrorReply(error="internal error while previewing", field="$"))
            return
        if kind == "reply":
            answer.reply(key, body)
        else:
            answer.error(msgspec_decode_error(body))

    def expire(self, now: float) -> None:
        """Answer every preview past its deadline with ``expired``, computed or not (a stuck one included)."""
        while self._deadlines and self._deadlines[0][0] + EXPIRY_GRACE_S <= now:
            _, ident, answer = heapq.heappop(self._deadlines)
            self._pending.pop(ident, None)
            answer.error(ErrorReply(error="expired: the preview's deadline passed before it was computed"))


# -- in the worker processes -------------------------------------------------------
_FIELD: dict[str, Any] = {}  # version -> threats, one field cached


def _compute(job: tuple[Any, ...], left_s: float, max_iter: int) -> tuple[str, bytes]:
    """One preview in a worker: ``("reply", body)`` or ``("error", ErrorReply JSON)``."""
    view, version, blob, payload, bounds, origin = job
    started = time.monotonic()
    try:
        if left_s <= 0:
            return "error", encode(ErrorReply(error="expired: the preview's deadline passed in the queue"))
        if _FIELD.get("version") != version:
            _FIELD.clear()
            _FIELD.update(version=version, threats=pickle.loads(blob))
        view = dataclasses.replace(view, threats=_FIELD["threats"])
        request = decode_preview_request(payload, bounds, origin)
        budget = 0.9 * left_s - (time.monotonic() - started)
        result = preview(view, request, time.monotonic, max(budget, 1e-3), max_iter)
        if request.geojson:
            return "reply", geojson.preview_reply(
                origin, result, view.threats, result.path[0], result.path[-1]
            )
        return "reply", fit_reply(result)
    except InputError as err:
        return "error", encode(ErrorReply.of(err))


def msgspec_decode_error(body: bytes) -> ErrorReply:
    from pfp_service.wire import decode_error_reply

    return decode_error_reply(body)


def warm_up(settings: WorldSettings | None) -> None:
    """Load (or compile) the numba kernels before serving, so no first direction or preview pays for it."""
    from pfp_service.service.world import World

    base = settings if settings is not None else WorldSettings()
    w = World(dataclasses.replace(base, deliberation="inline", bounds=None))
    threat = ThreatUpdate(position=(5.0, 5.0), sigma_range=1.0, sigma_lateral=0.7)
    out = w.apply(
        [
            ThreatPut("w", threat),
            StateReported("w", UnitState(position=(0.0, 0.0))),
            GoalSet("w", Goal(position=(10.0, 10.0))),
        ],
        0.0,
    )
    preview(w.view("w"), None, time.monotonic, 5.0, 10_000)
    assert out.directions
