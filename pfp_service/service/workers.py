"""Worker processes for the planner's off-loop work (previews, deliberation): started, warmed, never orphaned.

Both pools are ``spawn`` process pools (a fork of a process holding a Zenoh
session is unsafe).  Each worker loads the numba kernels once at start
(``warm_up``) and watches its parent: a planner that dies, even by
``SIGKILL``, takes its workers with it within ``ORPHAN_POLL_S`` -- before,
every killed planner left its workers running, a few hundred MB each.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor

__all__ = ["ORPHAN_POLL_S", "spawn_pool", "stop_pool"]

ORPHAN_POLL_S = 0.5


def spawn_pool(workers: int) -> tuple[ProcessPoolExecutor, list[Future[None]]]:
    """A pool of ``workers`` processes, started now; wait on the futures to know they are warm."""
    ctx = multiprocessing.get_context("spawn")  # never fork a process holding a zenoh session
    pool = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init, initargs=(os.getpid(),))
    return pool, [pool.submit(_noop) for _ in range(workers)]


def stop_pool(pool: ProcessPoolExecutor) -> None:
    """Stop at once: a worker still inside a job is terminated, not waited for."""
    procs = list((getattr(pool, "_processes", None) or {}).values())  # no public handle on them
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.terminate()


def _init(parent: int) -> None:
    threading.Thread(target=_watch_parent, args=(parent,), name="pfp-orphan-watch", daemon=True).start()
    from pfp_service.service.desk import warm_up

    warm_up(None)


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(ORPHAN_POLL_S)
    os._exit(0)  # the planner is gone: nobody will ask this worker anything again


def _noop() -> None:
    return None
