"""The preview service: previews admitted, ordered and answered by worker processes, each exactly once and in time.

The loop hands each preview query here with the unit's detached view
(``World.view``).  In the loop thread, before any work:

* the body is decoded and admitted (``preview.admit``): a request whose cost
  bound is out of proportion is refused, naming the field;
* a request that cannot start within ``wait_s`` of its arrival (the lane's
  queue times its measured run time, over the slots it may use) is answered
  ``busy`` at once with a retry hint, instead of waiting until it expires.

An admitted preview waits in its lane: light ones before heavy ones, and
heavy ones hold at most ``workers - 1`` slots, so a light preview never waits
behind a heavy one.  A worker computes it within ``budget_s`` from when it
starts: the walk checks its deadline every 64 steps, an alarm in the worker
stops any other phase (a route search, the metrics of a long path) just past
it, and ``WorkerPool`` kills a worker still busy ``KILL_GRACE_S`` later and
starts a fresh one in its slot.  Each worker's address space is bounded
(``WORKER_MEMORY_MB`` past its warm size): past it the preview is answered an
error and the worker replaced, never the planner.  Replies over the payload
limit are decimated (``fit_reply``).

Why processes: a preview is a Python stepping loop, and a thread running it
shares the GIL with the planning loop (measured: the live stream's p99 rose
from 18 ms to 185 ms under a 60-query storm with two preview threads, on a
loaded machine).  In its own process it shares nothing, and it can be killed.

Why two preview workers on a 2-core machine (``preview_workers``, default 2):
the planning loop needs one core, so more CPU-bound workers only time-slice
the other one (and cost ~150 MB each); two keep one slot for light previews
while a heavy one runs, and they run at a lower CPU priority than the loop
(``WORKER_NICE``), so the live stream keeps its latency under a storm.

Why one of them starts with the planner and the rest on first use: an
idle planner held 5 processes and ~520 MB (PSS), two of them preview
workers and one their warm spare.  One warm worker still answers the first
preview within its budget (warmed on the world's field, as ever); the
second and the spare start when the first preview arrives.  Under
``pfp serve`` every worker is forked from the warm fork server
(``forkserver.ForkServer``): it starts in 10-90 ms instead of 3-7 s (load
average 8) and costs about 2 MB of its own while idle, so the eager one
costs little and the first preview waits for no start at all.
"""

from __future__ import annotations

import contextlib
import dataclasses
import heapq
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from pfp_service.core.params import FieldStats, field_stats
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.node.config import ServeConfig
from pfp_service.node.log import get_logger
from pfp_service.node.preview_work import ALARM_GRACE_S, compute, compute_team
from pfp_service.node.tasks import Blobs, Outcome, Task
from pfp_service.node.warmup import forget_warm_worlds, warm_wide
from pfp_service.node.workers import WorkerPool
from pfp_service.wire import (
    ErrorReply,
    Goal,
    ThreatUpdate,
    UnitState,
    decode,
    decode_preview_request,
    encode,
    keys,
)
from pfp_service.wire.messages import Bounds, TeamPreviewRequest, ZoneUpdate
from pfp_service.world.events import GoalSet, StateReported, ThreatPut, UnitView, WorldSettings, ZonePut
from pfp_service.world.preview import Cost, admit, preview
from pfp_service.world.team_preview import TeamSeed
from pfp_service.world.team_preview import seed as team_seed
from pfp_service.world.world import World

__all__ = ["EXPIRY_GRACE_S", "WORKER_MEMORY_MB", "WORKER_NICE", "PreviewService", "warm_up"]

log = get_logger("previews")
_JSON = zenoh.Encoding.APPLICATION_JSON
EXPIRY_GRACE_S = 1.0  # a backstop: a preview unanswered this long past its last moment is answered "expired"
WORKER_MEMORY_MB = 1024.0  # address space a preview worker may add to its warm size (measured: ~0.3 GB used)
WORKER_NICE = 10  # preview workers yield the cores to the live loop
LIGHT, HEAVY = 0, 1
_FIRST_GUESS_S = {LIGHT: 0.02, HEAVY: 0.5}  # run time assumed before any is measured
_EWMA = 0.2
FAILURE_LOG_S = 60.0  # a preview failing the same way is logged once a minute
WARM_S = 3.0  # how long a worker takes to start, for the retry hint while every one is being replaced


class _Answer:
    """One preview query, answered exactly once."""

    def __init__(self, query: zenoh.Query, last: float) -> None:
        self.query = query
        self.last = last  # on the preview service's clock: answered by then, whatever happens
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
                self.query.drop()  # type: ignore[no-untyped-call]  # zenoh stub

    def error(self, err: ErrorReply) -> None:
        if self._claim():
            with contextlib.suppress(Exception):
                self.query.reply_err(encode(err), encoding=_JSON)
                self.query.drop()  # type: ignore[no-untyped-call]  # zenoh stub


class PreviewService:
    """Previews on ``workers`` processes, at most ``queue`` in flight, each started within ``wait_s``
    and computed within ``budget_s``.

    Args:
        clock: the node's monotonic clock (arrival times are on it).
        bounds, origin: the mission's, for decoding requests.
        wait_s: longest a preview may wait for a worker; one that could not start by then is
            answered ``busy`` at once.
        memory_mb: address space each worker may add to its warm size.
        team_budget_s: a team preview's budget instead of ``budget_s`` (a replay steps a world).
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
        wait_s: float = 2.0,
        memory_mb: float | None = WORKER_MEMORY_MB,
        team_budget_s: float = 5.0,
    ) -> None:
        self._queue_max = queue
        self._budget_s = budget_s
        self._team_budget_s = team_budget_s
        self._wait_s = wait_s
        self._max_iter = max_iter
        self._clock = clock
        self._bounds = bounds
        self._origin = origin
        self._blobs = Blobs()
        self._stats: tuple[tuple[Any, ...], FieldStats] | None = None
        self._logged: dict[str, float] = {}  # failure -> when last logged
        self._lock = threading.Lock()
        self._pending: dict[int, _Answer] = {}
        self._deadlines: list[tuple[float, int, _Answer]] = []
        self._run_s = dict(_FIRST_GUESS_S)
        self._pool = WorkerPool(
            "preview",
            workers,
            memory_mb=memory_mb,
            nice=WORKER_NICE,
            lane_caps={HEAVY: max(1, workers - 1)},
            warm="pfp_service.node.previews:_warm_worker",
            on_replaced=self._replaced,
            spare=True,
            eager=1,  # one worker waits warm; the others and the spare start with the first preview
        )

    def wait_ready(self, timeout_s: float = 180.0) -> None:
        """Block until every worker has loaded the kernels (the node calls it before serving)."""
        if not self._pool.wait_ready(timeout_s):
            log.error("preview workers not ready", extra={"fields": {"waited_s": timeout_s}})

    def shutdown(self) -> None:
        """Stop at once: a worker still inside a preview is killed, not waited for."""
        self._pool.shutdown()

    def refuse(self, query: zenoh.Query, err: ErrorReply) -> None:
        """Answer a query the loop will not compute (a bad key, say)."""
        _Answer(query, 0.0).error(err)

    def submit(self, query: zenoh.Query, key: str, view: UnitView, received: float) -> None:
        """Admit one preview and queue it in its lane, or answer it at once (refused, or busy)."""
        payload = query.payload.to_bytes() if query.payload is not None else b""
        try:
            request = decode_preview_request(payload, self._bounds, self._origin)
            cost = admit(view, request, self._max_iter, self._stats_of(view.threats))
        except InputError as err:
            self.refuse(query, ErrorReply.of(err))
            return
        blob = self._blobs.of(view.threats)
        job = (dataclasses.replace(view, threats=()), request, self._origin, self._budget_s, self._max_iter)
        lane = HEAVY if cost.heavy else LIGHT
        self._queue(query, key, compute, job, lane, _priority(cost), received, blob, self._budget_s)

    def team(self, query: zenoh.Query, world: World, received: float) -> None:
        """A team preview query: seeded from ``world`` in the loop thread (``team_preview.seed``), then queued.

        The planner guiding the team's lead (else its first member) answers; the others stay silent.
        """
        key = str(query.key_expr)
        try:
            tid = keys.parse(key).id
            team = world.teams.teams.get(tid)
            if team is not None and not world.owns(team.lead or min(team.units(), default=tid)):
                query.drop()  # type: ignore[no-untyped-call]  # zenoh stub
                return
            payload = query.payload.to_bytes() if query.payload is not None else b""
            request = decode(TeamPreviewRequest, payload) if payload else TeamPreviewRequest()
            seed = team_seed(world, tid, self._clock(), request)  # its horizon bounds the outsiders taken
            if seed is None:
                raise InputError("key", f"no team {tid!r} in force")
        except InputError as err:
            self.refuse(query, ErrorReply.of(err))
            return
        except Exception as exc:  # a bulkhead: this preview fails, the loop and every other answer go on
            log.exception("team preview seed failed", extra={"fields": {"key": key}})
            self.refuse(query, ErrorReply(error=f"the planner could not seed this team preview: {exc}"[:512]))
            return
        self.submit_team(query, key, seed, request, received)

    def submit_team(
        self, query: zenoh.Query, key: str, seed: TeamSeed, request: TeamPreviewRequest, received: float
    ) -> None:
        """Admit one team preview (``world.team_preview``) and queue it: heavy, a replay of every member and outsider."""
        steps = (len(seed.members) + len(seed.outsiders)) * request.horizon_s / request.dt_s
        job = (seed, request, self._team_budget_s)
        self._queue(query, key, compute_team, job, HEAVY, steps, received, None, self._team_budget_s)

    def _queue(
        self,
        query: zenoh.Query,
        key: str,
        fn: Callable[[Any], tuple[str, bytes]],
        job: tuple[Any, ...],
        lane: int,
        priority: float,
        received: float,
        blob: Any,
        budget_s: float,
    ) -> None:
        """Queue one admitted job in ``lane``, or answer ``busy`` at once if it could not start in time."""
        now = self._clock()
        start_by = received + self._wait_s
        wait = self._expected_wait(lane)
        if len(self._pending) >= self._queue_max or now + wait > start_by:
            self._busy(query, wait)
            return
        answer = _Answer(query, start_by + budget_s + ALARM_GRACE_S)
        with self._lock:
            self._pending[id(answer)] = answer
            heapq.heappush(self._deadlines, (answer.last, id(answer), answer))
        offset = time.monotonic() - now  # the pool's deadlines are on time.monotonic
        task = Task(
            fn,
            (job,),
            lambda out: self._done(out, answer=answer, key=key, lane=lane, wait=self._expected_wait(lane)),
            budget_s=budget_s + ALARM_GRACE_S,
            start_by=start_by + offset,
            field=blob,
            lane=lane,
            priority=priority,
        )
        self._pool.submit(task)

    def _stats_of(self, threats: tuple[Any, ...]) -> FieldStats:
        """``field_stats`` of the threats in force, once per field (admission derives steps from it)."""
        if self._stats is None or self._stats[0] is not threats:
            self._stats = (threats, field_stats(threats))
        return self._stats[1]

    def _expected_wait(self, lane: int) -> float:
        """How long a preview queued in ``lane`` now would wait for a worker (an estimate)."""
        pool = self._pool
        ready = pool.ready_slots()
        if ready == 0:
            return WARM_S  # every worker is being replaced
        ahead = pool.waiting(LIGHT) + (pool.waiting(HEAVY) if lane == HEAVY else 0)
        slots = pool.slots_for(lane) if lane == HEAVY else max(1, ready - pool.running(HEAVY))
        busy = pool.running(lane) >= slots
        return (ahead + busy) * self._run_s[lane] / slots

    def _busy(self, query: zenoh.Query, wait: float) -> None:
        self.refuse(
            query,
            ErrorReply(
                error=f"busy: the planner cannot start this preview in time; retry in {_retry_ms(wait)} ms"
            ),
        )

    def _done(self, out: Outcome, *, answer: _Answer, key: str, lane: int, wait: float) -> None:
        with self._lock:
            self._pending.pop(id(answer), None)
        if out.kind in ("done", "error", "memory", "killed"):
            self._run_s[lane] += _EWMA * (max(out.run_s, 1e-3) - self._run_s[lane])
        if out.kind == "done":
            kind, body = out.value
            if kind == "reply":
                answer.reply(key, body)
            else:
                answer.error(_decode_error(body))
        elif out.kind == "late":
            answer.error(
                ErrorReply(error=f"busy: the preview could not start in time; retry in {_retry_ms(wait)} ms")
            )
        elif out.kind == "killed":
            answer.error(ErrorReply(error="expired: the preview ran past its deadline and was stopped"))
        elif out.kind == "memory":
            answer.error(ErrorReply(error="too large: the preview ran out of its worker's memory"))
        elif out.kind == "closed":
            answer.error(ErrorReply(error="unavailable: the planner is shutting down"))
        else:
            self._log_failure(key, out)
            answer.error(ErrorReply(error="internal error while previewing", field="$"))

    def _log_failure(self, key: str, out: Outcome) -> None:
        """One line per kind of failure a minute: the exception's own line, not its traceback."""
        error = (out.detail.strip().splitlines() or [out.kind])[-1]
        now = time.monotonic()
        if now - self._logged.get(error, -math.inf) < FAILURE_LOG_S:
            return
        if len(self._logged) > 256:  # bounded: a storm of distinct failures is logged, not remembered
            self._logged.clear()
        self._logged[error] = now
        log.error("preview failed", extra={"fields": {"key": key, "why": out.kind, "error": error}})

    def _replaced(self, why: str) -> None:
        log.warning("preview worker replaced", extra={"fields": {"why": why}})

    def waiting(self) -> bool:
        """Whether a preview is still unanswered: the loop comes back for ``expire`` though nothing else is due."""
        with self._lock:
            return bool(self._deadlines)

    def expire(self, now: float) -> None:
        """Answer ``busy`` the previews still queued past their start, and (a backstop) ``expired`` any
        still unanswered well past its last moment."""
        self._pool.drop_late()
        with self._lock:
            while self._deadlines and self._deadlines[0][0] + EXPIRY_GRACE_S <= now:
                _, ident, answer = heapq.heappop(self._deadlines)
                self._pending.pop(ident, None)
                answer.error(
                    ErrorReply(error="expired: the preview's deadline passed before it was computed")
                )
            while self._deadlines and self._deadlines[0][2].done:  # answered: off the heap
                _, ident, _answer = heapq.heappop(self._deadlines)
                self._pending.pop(ident, None)


def _priority(cost: Cost) -> float:
    return max(cost.steps, cost.route_points) * (1 + cost.whatifs)


def _retry_ms(wait: float) -> int:
    return max(100, math.ceil(1e3 * min(wait, 60.0) / 100) * 100)


def _decode_error(body: bytes) -> ErrorReply:
    from pfp_service.wire import decode_error_reply

    return decode_error_reply(body)


# whether a worker warms the terrain's kernels: set by a planner without terrain before it forks its fork
# server (``run._fork_server``), so the workers forked from it skip them as it does
WORKERS_WARM_TERRAIN = [True]


def _warm_worker() -> None:
    warm_up(None, terrain=WORKERS_WARM_TERRAIN[0])


_WARMED: set[str] = set()  # what this process's warm-ups covered (``warm_once``)


def _warm_key(base: WorldSettings, terrain: bool) -> str:
    return repr((dataclasses.replace(base, deliberation="inline", bounds=None, terrain=None), terrain))


def warm_once(settings: WorldSettings) -> None:
    """``warm_up(settings)``, unless this process has already run it for the same planner.

    A planner with a fork server warmed before forking it (``run._fork_server``); a second pass
    would load no kernel, and its worlds' searches would peak the process's memory again, on top of
    the session's own by then (BENCHMARKS.md, "The warm-up's worlds forgotten").
    """
    if _warm_key(settings, settings.terrain is not None) not in _WARMED:
        warm_up(settings)


def warm_up(settings: WorldSettings | None, terrain: bool | None = None) -> None:
    """Load (or compile) the numba kernels before serving, so no first direction or preview pays for it.

    ``terrain``: the terrain's kernels (the sweep, the masked rows) too; ``None``: when ``settings`` has a terrain,
    or has none (``None``: every kernel, as a fresh clone's tests and a worker want them).  A planner without
    terrain never runs them, and loading them (with rasterio) cost its process 26 MB (BENCHMARKS.md).
    """
    from pfp_service.world.world import World

    if terrain is None:
        terrain = settings is None or settings.terrain is not None
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
    # and as a worker runs it: on the world's own field, with threats and with none (a fresh
    # install compiles these on first use, which a 500 ms budget cannot pay)
    preview(w.view("w"), None, time.monotonic, 5.0, 10_000, w.field)
    empty = World(dataclasses.replace(base, deliberation="inline", bounds=None))
    empty.apply(
        [StateReported("e", UnitState(position=(0.0, 0.0))), GoalSet("e", Goal(position=(10.0, 0.0)))], 0.0
    )
    preview(empty.view("e"), None, time.monotonic, 5.0, 10_000, empty.field)
    # and round a keep-out zone across the way: its step rule, barrier and route blocking (a first
    # zone preview in a cold worker compiles them otherwise, past a preview's budget)
    zoned = World(dataclasses.replace(base, deliberation="inline", bounds=None))
    wall = ZoneUpdate(polygon=[[(4.0, -3.0), (5.0, -3.0), (5.0, 3.0), (4.0, 3.0), (4.0, -3.0)]])
    zoned.apply(
        [
            ZonePut("z", wall),
            StateReported("z", UnitState(position=(0.0, 0.0))),
            GoalSet("z", Goal(position=(10.0, 0.0))),
        ],
        0.0,
    )
    preview(zoned.view("z"), None, time.monotonic, 5.0, 10_000, zoned.field)
    assert out.directions
    # and what only a big world reaches: many threats, shared routes, storms, terrain (when it has one)
    warm_wide(base, terrain)
    forget_warm_worlds()  # their routes and freed pages: no caller keeps them
    _WARMED.add(_warm_key(base, terrain))


def preview_service(cfg: ServeConfig, clock: Callable[[], float] = time.monotonic) -> PreviewService:
    """The preview service of a planner of ``cfg``: its worker processes start warming up now."""
    return PreviewService(
        cfg.preview_workers,
        cfg.preview_queue,
        cfg.preview_budget_ms / 1e3,
        cfg.preview_max_iter,
        clock,
        cfg.bounds_tuple(),
        cfg.origin,
        wait_s=cfg.preview_wait_ms / 1e3,
        team_budget_s=cfg.team_preview_budget_ms / 1e3,
    )
