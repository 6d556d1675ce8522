"""Deliberation off the loop: the world's jobs run in worker processes, latest wins.

The world emits a ``Job`` (a detached stepper copy, the field it was asked
under, a deadline) whenever a unit needs its look-ahead or an escape search.
The loop hands the tick's jobs to ``Deliberators.submit`` and calls
``feed()`` every tick:

* jobs wait here, not in the pool: escape searches (a unit is trapped now)
  before look-aheads, oldest first.  At most ``workers * AHEAD`` chunks are
  in the pool at once, so a job superseded while it waits (a newer goal or
  world: the world's ``Outputs.cancelled``, passed to ``cancel``) is dropped
  before it costs anything, and one still waiting at its deadline is
  answered ``Deliberated(..., None)`` unrun, which the world takes as "ask
  again later";
* a chunk is up to ``CHUNK`` jobs under one field, so a storm of 1,000 costs
  125 round trips, not 1,000;
* each field's threats are pickled once and cached in the workers, so a job
  ships only its stepper copy;
* results come back through ``deliver`` (the node's inbox) and are applied at
  the next tick, where the world adopts them only if their token is still in
  force.

Why processes: a look-ahead or a route search is seconds of Python and numpy
under a storm, and a thread running it shares the GIL with the loop, the
Zenoh callbacks and the publishing (measured: with the deliberation thread
busy, the loop held the GIL 46 % of the time and the deliberation 30 %, and
the planner answered 30 % of 10,000 states/s).  In its own process it
shares only the machine's cores.  The processes are a ``WorkerPool``
(``workers.py``, shared with the preview service): a chunk still running
``CHUNK_RUN_S`` after it started is killed with its worker (its jobs are
asked again later), and each worker's memory is bounded.

The workers start with the first job, not with the planner: they are
forked from the planner's fork server (``forkserver.ForkServer``), warm and
sharing its pages, in milliseconds (a fresh interpreter, where no fork
server runs, takes seconds); a job still waiting at its deadline is
answered unrun and asked again, as under any backlog.  One worker by default
(``deliberation_workers``): on a 2-core machine the loop and the Zenoh
threads need a core, the preview workers share the other.
"""

from __future__ import annotations

import heapq
import time
import traceback
from collections.abc import Callable
from typing import Any

from pfp_service.core import ThreatField
from pfp_service.core.stepper import Stepper
from pfp_service.node.log import get_logger
from pfp_service.node.tasks import Blobs, Outcome, Task
from pfp_service.node.workerproc import world_field
from pfp_service.node.workers import WorkerPool
from pfp_service.world.events import Deliberated, Job

__all__ = ["AHEAD", "CHUNK", "CHUNK_RUN_S", "Deliberators"]

log = get_logger("deliberation")
CHUNK = 8  # jobs per round trip to a worker
AHEAD = 2  # chunks in the pool per worker; the rest wait here, where cancelling is free
_PRIORITY = {"escape": 0, "foresee": 1}  # a unit trapped now before a look-ahead
CHUNK_RUN_S = 60.0  # a chunk still running this long after it started is killed: a runaway, not a search
WORKER_MEMORY_MB = 1024.0  # address space a deliberation worker may add to its warm size
WORKER_NICE = 5  # below the live loop, above the preview workers
SWEEP_MIN = 256  # cancelled jobs the queue may hold before it is swept, whatever its length


class Deliberators:
    """Worker processes for the world's deliberation jobs.

    Args:
        workers: processes.
        clock: the node's monotonic clock (job deadlines are on it).
        deliver: called with each ``Deliberated`` from a pool thread (the node's inbox).
    """

    def __init__(
        self, workers: int, clock: Callable[[], float], deliver: Callable[[Deliberated], None]
    ) -> None:
        self._workers = workers
        self._clock = clock
        self._deliver = deliver
        self._waiting: list[tuple[int, int, Job]] = []  # (priority, seq, job)
        self._seq = 0
        self._cancelled = 0  # jobs cancelled since the queue was last swept (some had already left it)
        self._in_flight = 0  # chunks in the pool (only the loop thread changes it, in feed and _done)
        self._blobs = Blobs()
        self._closed = False
        self._logged_at = -float("inf")
        self._unlogged = 0
        self._finished: list[int] = []  # chunks done since the last feed (appended by pool threads)
        self._pool = WorkerPool(
            "deliberation",
            workers,
            memory_mb=WORKER_MEMORY_MB,
            nice=WORKER_NICE,
            warm="pfp_service.node.deliberation:_warm_worker",
            on_replaced=lambda why: log.warning(
                "deliberation worker replaced", extra={"fields": {"why": why}}
            ),
            eager=0,  # started by the first job: an idle planner holds no deliberation worker
        )  # jobs sent meanwhile wait for the workers

    def submit(self, jobs: list[Job]) -> None:
        """Queue the tick's jobs (the loop thread); ``feed`` sends them on."""
        for job in jobs:
            self._seq += 1
            heapq.heappush(self._waiting, (_PRIORITY.get(job.kind, 1), self._seq, job))

    def cancel(self, jobs: list[Job]) -> None:
        """The world no longer wants these jobs (``Outputs.cancelled``): one still waiting is dropped unrun.

        A cancelled job leaves the queue when it comes to the top, or sooner: once more jobs were
        cancelled since the last sweep than half the queue (and ``SWEEP_MIN``), the queue is rebuilt
        without them.  So wave after wave of superseded look-aheads, while the worker is behind,
        cannot grow it past about twice the jobs still wanted, nor keep their old fields alive.
        """
        for job in jobs:
            job.cancelled = True
        self._cancelled += len(jobs)
        if self._cancelled > max(SWEEP_MIN, len(self._waiting) // 2):
            self._waiting = [item for item in self._waiting if not item[2].cancelled]
            heapq.heapify(self._waiting)  # (priority, seq) keys are unique: the same order as before
            self._cancelled = 0

    def waiting(self) -> bool:
        """Whether jobs wait for a worker: the loop comes back to ``feed`` them (or answer the late ones)."""
        return bool(self._waiting)

    def feed(self) -> None:
        """Send waiting jobs to the pool while it has room; drop superseded ones, answer late ones."""
        while self._finished:
            self._finished.pop()
            self._in_flight -= 1
        now = self._clock()
        while self._waiting and self._in_flight < self._workers * AHEAD:
            field: ThreatField | None = None
            chunk: list[Job] = []
            while self._waiting and len(chunk) < CHUNK:
                job = self._waiting[0][2]
                if job.cancelled:
                    heapq.heappop(self._waiting)
                    continue
                if now > job.deadline:
                    heapq.heappop(self._waiting)
                    self._deliver(Deliberated(job.unit, job.token, None))
                    continue
                if field is not None and job.field is not field:
                    break  # a chunk runs under one field
                field = job.field
                chunk.append(heapq.heappop(self._waiting)[2])
            if not chunk:
                break
            self._send(chunk, now)

    def _send(self, chunk: list[Job], now: float) -> None:
        field = chunk[0].field
        items = [(j.unit, j.token, j.kind, j.detach(), j.deadline - now) for j in chunk]  # the copy, at last
        task = Task(
            _run_chunk,
            (field.intensity, items, field.zones, field.sight),
            lambda out: self._done(out, chunk=chunk),
            budget_s=CHUNK_RUN_S,
            field=self._blobs.of(field.threats),
        )
        self._in_flight += 1
        self._pool.submit(task)

    def _done(self, out: Outcome, *, chunk: list[Job]) -> None:
        if self._closed:
            return
        if out.kind == "done":
            results: list[tuple[Deliberated | None, str]] = out.value
        else:  # killed, out of memory, died, or the pool shut down: each job is asked again later
            results = [(None, f"{out.kind}: {out.detail}")] * len(chunk)
        for job, (done, error) in zip(chunk, results):
            if error:
                self._log_failure(job, error)
            self._deliver(done if done is not None else Deliberated(job.unit, job.token, None))
        self._finished.append(1)

    def _log_failure(self, job: Job, error: str) -> None:
        """At most one line a second, with how many failed since the last (a failing job is asked again)."""
        now = time.monotonic()
        self._unlogged += 1
        if now - self._logged_at < 1.0:
            return
        fields = {"unit": job.unit, "kind": job.kind, "failed": self._unlogged, "error": error}
        log.error("deliberation failed", extra={"fields": fields})
        self._logged_at, self._unlogged = now, 0

    def shutdown(self) -> None:
        """Stop at once: a worker inside a search is killed, not waited for."""
        self._closed = True
        self._pool.shutdown()


# -- in the worker processes -------------------------------------------------------
def _run_chunk(
    intensity: str,
    items: list[tuple[str, tuple[int, int], str, Stepper, float]],
    zones: Any = None,
    sight: Any = None,
) -> list[tuple[Deliberated | None, str]]:
    """``Job.run`` for each item under the field in force (its keep-out zones, its terrain's sight), each by
    its own deadline.

    An error comes back as text.
    """
    started = time.monotonic()
    field = world_field(intensity, sight)
    if (
        zones
    ):  # pickled with the chunk, its bytes made once a set (``ZoneSet.__reduce__``), unpickled once a worker
        field = field.with_zones(zones)
    out: list[tuple[Deliberated | None, str]] = []
    for unit, token, kind, stepper, left_s in items:
        try:
            out.append((Job(unit, token, kind, stepper, field, started + left_s).run(time.monotonic()), ""))
        except Exception:
            out.append((None, traceback.format_exc(limit=3)))
    return out


def _warm_worker() -> None:
    from pfp_service.node.previews import WORKERS_WARM_TERRAIN, warm_up

    warm_up(None, terrain=WORKERS_WARM_TERRAIN[0])
