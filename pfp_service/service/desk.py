"""The preview desk: previews answered on a pool of threads, each exactly once and within its deadline.

The loop hands each preview query here with the unit's detached view
(``World.view``).  A worker computes it with ``preview()`` within what is
left of the query's budget; the loop calls ``expire(now)`` every tick and
answers ``expired`` any query still unanswered past its deadline, even while
its worker is stuck in it.  Whichever comes first answers; the other is a
no-op.  Replies over the payload limit are decimated (``fit_reply``).
"""

from __future__ import annotations

import contextlib
import heapq
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import zenoh

from pfp_service import geojson
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.service.events import GoalSet, StateReported, ThreatPut, UnitView, WorldSettings
from pfp_service.service.log import get_logger
from pfp_service.service.preview import fit_reply, preview
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
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="pfp-preview")
        self._queue = queue
        self._budget_s = budget_s
        self._max_iter = max_iter
        self._clock = clock
        self._bounds = bounds
        self._origin = origin
        self._pending: dict[int, _Answer] = {}
        self._deadlines: list[tuple[float, int, _Answer]] = []

    def shutdown(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

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
        self._pool.submit(self._work, answer, key, view, payload)

    def expire(self, now: float) -> None:
        """Answer every preview past its deadline with ``expired``, computed or not (a stuck one included)."""
        while self._deadlines and self._deadlines[0][0] + EXPIRY_GRACE_S <= now:
            _, ident, answer = heapq.heappop(self._deadlines)
            self._pending.pop(ident, None)
            answer.error(ErrorReply(error="expired: the preview's deadline passed before it was computed"))

    def _work(self, answer: _Answer, key: str, view: UnitView, payload: bytes) -> None:
        try:
            left = answer.deadline - self._clock()
            if left <= 0 or answer.done:
                answer.error(ErrorReply(error="expired: the preview's deadline passed in the queue"))
                return
            request = decode_preview_request(payload, self._bounds, self._origin)
            result = preview(view, request, self._clock, 0.9 * left, self._max_iter)
            if request.geojson:
                body = geojson.preview_reply(
                    self._origin, result, view.threats, result.path[0], result.path[-1]
                )
            else:
                body = fit_reply(result)
            answer.reply(key, body)
        except InputError as err:
            answer.error(ErrorReply.of(err))
        except Exception:
            log.exception("preview failed", extra={"fields": {"key": key}})
            answer.error(ErrorReply(error="internal error while previewing", field="$"))


def warm_up(settings: WorldSettings) -> None:
    """Load (or compile) the numba kernels before serving, so no first direction or preview pays for it."""
    import dataclasses

    from pfp_service.service.world import World

    w = World(dataclasses.replace(settings, deliberation="inline", bounds=None))
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
