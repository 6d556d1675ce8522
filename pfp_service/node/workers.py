"""Worker processes for the planner's off-loop work (previews, deliberation): one small pool both use.

A ``WorkerPool`` runs each worker as a fork of the fork server ``pfp serve``
forked before its Zenoh session opened (``forkserver.ForkServer``; a fork of a process
holding a Zenoh session is unsafe), or where there is none as its own fresh
interpreter, with its own socket pipe, driven by one parent thread per slot.  The slot thread takes the next task, sends it,
waits for the result until the task's hard stop (its budget plus
``KILL_GRACE_S``), and past it kills that one process, answers the task
``killed`` and starts a fresh worker in the slot.  Why not a
``ProcessPoolExecutor``: it cannot stop one task -- a preview answered
``expired`` kept computing and the planner's process tree grew to 8 GB --
and terminating its processes breaks every other task in the pool.

Each worker:

* loads the numba kernels once (``warm_up``) before it takes a task;
* ignores SIGINT (Ctrl-C to the process group reaches it: the parent shuts
  it down, no traceback) and watches its planner, so a planner that dies,
  even by ``SIGKILL``, takes it along (a forked worker at once, by its
  lifeline pipe; a fresh interpreter within ``ORPHAN_POLL_S``);
* runs at a lower CPU priority (``nice``), so the live loop wins the cores;
* has its address space bounded (``RLIMIT_AS``: its size once warm, plus
  ``memory_mb``).  An allocation past it raises ``MemoryError`` in the task,
  which is answered ``memory``, and the worker is replaced (its heap may be
  left fragmented at the limit), never the planner;
* caches the threats in force (``FieldBlob``: pickled once per field by
  ``Blobs`` in the parent, shipped to a worker only when it lacks that
  version) and the ``ThreatField`` built on them (``world_field``), so
  every task under one world shares its culled field and route cache.

Tasks wait in lanes (``Task.lane``), each a heap by ``(priority, seq)``; a
free slot takes from the lowest lane first, and a lane may be capped to a
number of slots (``lane_caps``), so heavy work never holds every slot.  A
task not started by its ``start_by`` is answered ``late`` unrun.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import json
import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

from pfp_service.node.forkserver import installed_fork_server
from pfp_service.node.log import get_logger
from pfp_service.node.tasks import Outcome, OutcomeKind, Task
from pfp_service.node.workerproc import ORPHAN_POLL_S

__all__ = [
    "KILL_GRACE_S",
    "ORPHAN_POLL_S",
    "WorkerPool",
]

log = get_logger("workers")
KILL_GRACE_S = 0.25  # a task this long past its budget is killed with its worker
READY_TIMEOUT_S = 180.0  # a worker not warm by then is started again


@dataclass
class _Slot:
    index: int
    proc: Any = None
    conn: Connection | None = None
    version: int = -1  # the field version its worker holds
    task: Task | None = None
    thread: threading.Thread | None = None
    started: int = field(default=0)  # workers started in this slot
    ready: bool = False  # a warm worker is in it
    # taking ``proc``/``conn`` out is atomic under it: the starter (failing) and a shutdown (stopping)
    # may race for the same handles, and a connection closed twice could close a reused descriptor
    handles: threading.Lock = field(default_factory=threading.Lock)

    def take(self) -> tuple[Any, Connection | None]:
        """The slot's process and connection, now the caller's alone to stop and close."""
        with self.handles:
            proc, conn = self.proc, self.conn
            self.proc, self.conn, self.version, self.ready = None, None, -1, False
        return proc, conn


class WorkerPool:
    """``workers`` processes, each task on one of them, each killable alone.

    Args:
        name: for thread names and log lines.
        workers: processes.
        memory_mb: address space each worker may add to its warm size; ``None``: unbounded.
        nice: CPU priority added to each worker (0: as the planner).
        lane_caps: slots a lane may hold at once (lanes not named: every slot).
        warm: ``"module:function"``, run once in each worker before its first task.
        on_replaced: called with the reason each time a worker is killed or replaced.
        spare: keep one more warm worker aside, so a killed worker's slot is free again at once.
        eager: slots whose workers start at once (default: every slot); the other slots' workers,
            and the spare, start when the first task is submitted.  ``wait_ready`` waits for
            the eager ones only.
    """

    def __init__(
        self,
        name: str,
        workers: int,
        *,
        memory_mb: float | None = None,
        nice: int = 0,
        lane_caps: Mapping[int, int] | None = None,
        warm: str | None = None,
        on_replaced: Callable[[str], None] | None = None,
        spare: bool = False,
        eager: int | None = None,
    ) -> None:
        self.name = name
        self._memory_mb = memory_mb
        self._nice = nice
        self._caps = dict(lane_caps or {})
        self._warm = warm
        self._forker = installed_fork_server()
        self._on_replaced = on_replaced
        self._cond = threading.Condition()
        self._lanes: dict[int, list[tuple[float, int, Task]]] = {}
        self._running: dict[int, int] = {}  # lane -> tasks running
        self._seq = itertools.count()
        self._closed = False
        self._ready = threading.Event()
        self._eager = workers if eager is None else max(0, min(eager, workers))
        self._woken = self._eager >= workers  # a task was submitted: every slot starts its worker
        self._warm_left = self._eager
        if self._warm_left == 0:
            self._ready.set()
        self.replaced = 0
        self._spare: tuple[Any, Connection, int] | None = None
        self._slots = [_Slot(i) for i in range(workers)]
        if spare:
            threading.Thread(target=self._keep_spare, name=f"pfp-{name}-spare", daemon=True).start()
        for slot in self._slots:
            slot.thread = threading.Thread(target=self._serve, args=(slot,), name=f"pfp-{name}-{slot.index}")
            slot.thread.daemon = True
            slot.thread.start()

    # -- the parent's API ---------------------------------------------------------------
    @property
    def workers(self) -> int:
        return len(self._slots)

    def wait_ready(self, timeout_s: float = READY_TIMEOUT_S) -> bool:
        """Block until every worker is warm (or ``timeout_s``); true if they are."""
        return self._ready.wait(timeout_s)

    def submit(self, task: Task) -> None:
        """Queue ``task``; a closed pool answers it ``closed`` at once."""
        with self._cond:
            if not self._closed:
                heapq.heappush(self._lanes.setdefault(task.lane, []), (task.priority, next(self._seq), task))
                self._woken = True  # the lazy slots start their workers now
                self._cond.notify_all()  # the spare keeper waits on it too
                return
        _finish(task, Outcome("closed", detail="the planner is shutting down"))

    def waiting(self, lane: int) -> int:
        """Tasks queued in ``lane``, not yet started."""
        with self._cond:
            return len(self._lanes.get(lane, ()))

    def running(self, lane: int | None = None) -> int:
        """Tasks running (in ``lane``, or in all)."""
        with self._cond:
            return sum(self._running.values()) if lane is None else self._running.get(lane, 0)

    def ready_slots(self) -> int:
        """Slots with a warm worker (a killed one's successor may still be warming)."""
        return sum(1 for s in self._slots if s.ready)

    def drop_late(self) -> int:
        """Answer ``late`` every queued task past its ``start_by`` (while every slot is busy or warming)."""
        now = time.monotonic()
        late: list[Task] = []
        with self._cond:
            for lane, heap in self._lanes.items():
                keep = [item for item in heap if item[2].start_by >= now]
                if len(keep) < len(heap):
                    late += [item[2] for item in heap if item[2].start_by < now]
                    heapq.heapify(keep)
                    self._lanes[lane] = keep
        for task in late:
            _finish(task, Outcome("late", detail="not started within its deadline"))
        return len(late)

    def slots_for(self, lane: int) -> int:
        """Slots ``lane`` may hold at once."""
        return min(self._caps.get(lane, len(self._slots)), len(self._slots))

    def pids(self) -> list[int]:
        """The workers' process ids (those running now)."""
        spare = self._spare
        procs = [s.proc for s in self._slots] + [spare[0] if spare is not None else None]
        return [p.pid for p in procs if p is not None and p.poll() is None]

    def shutdown(self) -> None:
        """Stop at once: queued tasks are answered ``closed``, a worker inside a task is killed."""
        with self._cond:
            self._closed = True
            queued = [t for lane in self._lanes.values() for _, _, t in lane]
            self._lanes.clear()
            self._cond.notify_all()
        for task in queued:
            _finish(task, Outcome("closed", detail="the planner is shutting down"))
        for slot in self._slots:
            self._stop_worker(slot)
        with self._cond:
            spare, self._spare = self._spare, None
            self._cond.notify_all()
        if spare is not None:
            with contextlib.suppress(Exception):
                spare[0].kill()
                spare[0].wait(timeout=2.0)

    # -- the slot threads ----------------------------------------------------------------
    def _next(self) -> Task | None:
        """The next task a free slot may take (under the lock), or ``None``."""
        for lane in sorted(self._lanes):
            heap = self._lanes[lane]
            if heap and self._running.get(lane, 0) < self.slots_for(lane):
                task = heapq.heappop(heap)[2]
                self._running[lane] = self._running.get(lane, 0) + 1
                return task
        return None

    def _serve(self, slot: _Slot) -> None:
        _block_sigint()
        with self._cond:
            while slot.index >= self._eager and not self._woken and not self._closed:
                self._cond.wait()  # a lazy slot: its worker starts with the pool's first task
        while True:
            if not self._ensure_worker(slot):
                return
            with self._cond:
                task = self._next()
                while task is None and not self._closed:
                    self._cond.wait()
                    task = self._next()
                if self._closed:
                    return
            assert task is not None
            try:
                self._run(slot, task)
            except Exception as exc:  # a bug of ours: the task is answered, the slot carries on
                log.error(
                    "worker pool failed a task", extra={"fields": {"pool": self.name, "error": repr(exc)}}
                )
                self._replace(slot, f"internal error: {type(exc).__name__}")
                _finish(task, Outcome("died", detail=f"internal error: {type(exc).__name__}"))
            finally:
                with self._cond:
                    self._running[task.lane] -= 1
                    self._cond.notify_all()

    def _run(self, slot: _Slot, task: Task) -> None:
        if task.skip is not None and task.skip():
            return
        now = time.monotonic()
        if now > task.start_by:
            _finish(
                task,
                Outcome("late", detail=f"not started within its deadline ({now - task.start_by:.3f} s late)"),
            )
            return
        blob = task.field
        ship = None
        if blob is not None and blob.version != slot.version:
            ship = blob.data
        version = blob.version if blob is not None else -1
        conn = slot.conn
        assert conn is not None
        try:
            conn.send((task.fn, task.args, version, ship))
        except (
            OSError,
            ValueError,
            pickle.PicklingError,
            TypeError,
        ) as exc:  # gone, or args that won't pickle
            self._replace(slot, f"send failed: {type(exc).__name__}")
            _finish(task, Outcome("died", detail=f"the worker could not take the task: {type(exc).__name__}"))
            return
        if blob is not None:
            slot.version = version
        hard_stop = time.monotonic() + task.budget_s + KILL_GRACE_S
        got: tuple[Any, Any, float, bool] | None = None
        try:
            while got is None:
                left = hard_stop - time.monotonic()
                if left <= 0 or self._closed:
                    break
                if conn.poll(min(left, 0.5)):
                    got = conn.recv()
        except (EOFError, OSError):  # the worker died mid-task (a signal, the OOM killer)
            self._replace(slot, "died")
            _finish(task, Outcome("died", detail="the worker died during the task"))
            return
        if got is None:
            self._replace(slot, "killed past its budget")
            _finish(
                task,
                Outcome(
                    "killed", detail=f"still running {task.budget_s + KILL_GRACE_S:.2f} s after it started"
                ),
            )
            return
        kind: OutcomeKind
        kind, value, run_s, retired = got
        if kind == "memory":
            self._replace(slot, "memory limit")
        elif retired:
            self._replace(slot, "retired after its task (it was interrupted)")
        _finish(
            task,
            Outcome(kind, value if kind == "done" else None, "" if kind == "done" else str(value), run_s),
        )

    def _replace(self, slot: _Slot, why: str) -> None:
        self._stop_worker(slot)
        self.replaced += 1
        if self._on_replaced is not None:
            with contextlib.suppress(Exception):
                self._on_replaced(why)

    def _stop_worker(self, slot: _Slot) -> None:
        proc, conn = slot.take()
        if proc is not None:
            with contextlib.suppress(Exception):
                proc.kill()
            with contextlib.suppress(Exception):
                proc.wait(timeout=2.0)
        if conn is not None:
            with contextlib.suppress(Exception):
                conn.close()

    def _ensure_worker(self, slot: _Slot) -> bool:
        """A warm worker in ``slot`` (the spare, or one started now); false once the pool is closed."""
        while slot.proc is None or slot.proc.poll() is not None:
            if self._closed:
                return False
            if slot.proc is not None:
                self._stop_worker(slot)
            with self._cond:
                got, self._spare = self._spare, None
                self._cond.notify_all()  # the spare keeper starts the next one
            if got is None:
                got = self._start_worker(slot)
            if got is None:
                time.sleep(0.5)  # a worker that cannot start: not in a tight loop
                continue
            with slot.handles:
                slot.proc, slot.conn, slot.version = got
            slot.started += 1
            if self._closed:
                self._stop_worker(slot)
                return False
            slot.ready = True
            with self._cond:
                if slot.started == 1:
                    self._warm_left -= 1
                    if self._warm_left == 0:
                        self._ready.set()
        return True

    def _start_worker(self, slot: _Slot | None) -> tuple[Any, Connection, int] | None:
        """A new worker, warm (``slot`` shows it meanwhile, so a shutdown can kill it); ``None`` if it failed.

        Forked by the fork server where there is one (``ForkServer``), else a fresh interpreter."""
        ours_sock, theirs_sock = socket.socketpair()
        ours = Connection(ours_sock.detach())
        theirs = theirs_sock.detach()
        proc: Any = None
        if self._forker is not None:
            proc = self._forker.spawn(theirs, self._memory_mb, self._nice)
        if proc is None:
            boot = [os.getpid(), theirs, self._memory_mb, self._nice, self._warm]
            code = "import sys; from pfp_service.node.workerproc import boot; boot(sys.argv[1])"
            try:
                # a fresh interpreter, not multiprocessing's spawn: it keeps the SIGINT blocked in this
                # thread (``_block_sigint``) until it ignores it, and it imports no __main__ of ours
                proc = subprocess.Popen(
                    [sys.executable, "-c", code, json.dumps(boot)],
                    pass_fds=(theirs,),
                    stdin=subprocess.DEVNULL,
                )
            except Exception:  # no process to be had now (out of memory, too many processes)
                os.close(theirs)
                ours.close()
                return None
        os.close(theirs)
        if slot is not None:
            with slot.handles:
                slot.proc, slot.conn = proc, ours
        try:
            ok = ours.poll(READY_TIMEOUT_S) and ours.recv() == "ready"
        except (EOFError, OSError):  # a shutdown may have closed it under us (it then owns both)
            ok = False
        if not ok or self._closed:
            if slot is None:
                mine = True
            else:  # a shutdown that took the handles first stops and closes them itself
                with slot.handles:
                    mine = slot.conn is ours
                    if mine:
                        slot.proc, slot.conn = None, None
            if mine:
                with contextlib.suppress(Exception):
                    proc.kill()
                    proc.wait(timeout=2.0)
                ours.close()
            return None
        return proc, ours, -1

    def _keep_spare(self) -> None:
        """Keep one warm worker aside, so a killed one is replaced at once, not after a warm-up."""
        _block_sigint()
        self._ready.wait()
        with self._cond:  # with lazy slots the spare waits for them: it is started last
            while not self._woken and not self._closed:
                self._cond.wait()
        while True:
            with self._cond:  # a slot's own successor first: two warming at once take twice as long
                while (self._spare is not None or not all(x.ready for x in self._slots)) and not self._closed:
                    self._cond.wait(1.0)
                if self._closed:
                    return
            got = self._start_worker(None)
            if got is None:
                time.sleep(1.0)
                continue
            with self._cond:
                if not self._closed:
                    self._spare = got
                    continue
            with contextlib.suppress(Exception):
                got[0].kill()
            return


def _finish(task: Task, out: Outcome) -> None:
    """Answer ``task`` once: a second answer (a bug) is dropped, and its callback's failure logged, not raised."""
    if task.answered:
        return
    task.answered = True
    try:
        task.done(out)
    except Exception as exc:
        log.error("a task's answer failed", extra={"fields": {"outcome": out.kind, "error": repr(exc)}})


def _block_sigint() -> None:
    """Block SIGINT in a thread that starts workers: a worker inherits the mask, so a Ctrl-C to the
    process group while it is still importing (before it can ignore SIGINT) leaves it be, and the
    parent stops it; Python handles signals on the main thread only, so the thread loses nothing."""
    with contextlib.suppress(AttributeError, OSError, ValueError):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
