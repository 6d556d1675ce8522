"""A worker process's side of the pool: its entry point, its limits, and the field its tasks share.

``workers.WorkerPool`` starts ``python -c "...; boot(ARG)"``, so this module is
what a worker imports first; nothing in the planner's process imports it but
the tasks that run in workers (``world_field``, ``retire``).  Where the planner
forked a fork server (``forkserver.ForkServer``), ``serve_forks`` is its loop, and each
worker it forks enters ``_worker_main`` from there, already warm.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import pickle
import select
import signal
import socket
import threading
import time
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

from pfp_service.node.log import get_logger

__all__ = ["ORPHAN_POLL_S", "boot", "forget_fields", "retire", "serve_forks", "world_field", "world_threats"]

log = get_logger("workers")
ORPHAN_POLL_S = 0.5  # a fresh-interpreter worker checks its parent this often

# -- in the worker processes -------------------------------------------------------------
_WORLD: dict[str, Any] = {"version": None, "threats": (), "fields": {}}


def world_threats() -> tuple[Any, ...]:
    """The threats the current task runs under (its ``Task.field``)."""
    return _WORLD["threats"]  # type: ignore[no-any-return]


def world_field(intensity: str, sight: Any = None) -> Any:
    """The ``ThreatField`` of ``world_threats()``, built once per field, intensity and sight (the terrain's,
    ``core.visibility``), shared by every task."""
    fields = _WORLD["fields"]
    got = fields.get((intensity, sight))
    if got is None:
        from pfp_service.core import ThreatField

        got = fields[(intensity, sight)] = ThreatField(_WORLD["threats"], intensity, sight=sight)  # type: ignore[arg-type]
    return got


_RETIRE = [False]


def forget_fields() -> None:
    """Drop the fields built on the threats in force (built again when next asked)."""
    _WORLD["fields"] = {}


def retire() -> None:
    """Have this worker replaced once its task has replied (a task that was interrupted mid-phase calls it)."""
    _RETIRE[0] = True


def boot(arg: str) -> None:
    """A worker's entry point (``python -c``): ``arg`` is ``[parent, fd, memory_mb, nice, warm]`` as JSON."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent stops us
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked while it started (_block_sigint)
    parent, fd, memory_mb, nice, warm = json.loads(arg)
    fn = None
    if warm is not None:
        module, _, name = warm.partition(":")
        fn = getattr(importlib.import_module(module), name)
    _worker_main(Connection(fd), parent, memory_mb, nice, fn)


def serve_forks(sock: socket.socket, lifeline: int) -> None:
    """The fork server's loop (``forkserver.ForkServer``): fork one worker per request, until the planner goes.

    A request is ``[memory_mb, nice]`` with the worker's socket end; the reply is its process id.
    The planner's end of ``sock`` and of ``lifeline`` close when it dies: either ends the loop.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the planner stops us
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the planner's handlers would only set its stop event
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # its workers are reaped by the kernel
    while True:
        ready, _, _ = select.select([sock.fileno(), lifeline], [], [])
        if lifeline in ready:
            return
        try:
            msg, fds, _, _ = socket.recv_fds(sock, 1024, 1)
        except OSError:
            return
        if not msg or not fds:
            return
        memory_mb, nice = json.loads(msg)
        try:
            pid = os.fork()
        except OSError:  # answered "x": the pool starts this one as a fresh interpreter
            pid = -1
        if pid == 0:  # the worker: it never returns into the fork server's loop
            code = 1
            try:
                sock.close()
                signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                threading.Thread(
                    target=_watch_lifeline, args=(lifeline,), name="pfp-orphan-watch", daemon=True
                ).start()
                _worker_main(Connection(fds[0]), None, memory_mb, nice, None)
                code = 0
            finally:
                os._exit(code)
        os.close(fds[0])
        try:
            sock.sendall(str(pid).encode() if pid > 0 else b"x")
        except OSError:
            return


def _watch_lifeline(fd: int) -> None:
    with contextlib.suppress(OSError):
        while os.read(fd, 1):
            pass
    os._exit(0)  # the planner is gone (its end of the pipe closed): nobody will ask again


def _worker_main(
    conn: Connection, parent: int | None, memory_mb: float | None, nice: int, warm: Callable[[], None] | None
) -> None:
    if parent is not None:  # a forked worker watches the lifeline instead (``serve_forks``)
        threading.Thread(target=_watch_parent, args=(parent,), name="pfp-orphan-watch", daemon=True).start()
    if warm is not None:
        warm()  # at the planner's priority: a killed worker's successor is wanted soon
    if nice:
        with contextlib.suppress(OSError):
            os.nice(nice)
    if memory_mb is not None:
        _limit_address_space(memory_mb)
    try:
        conn.send("ready")
    except OSError:  # the planner went while this worker was starting (a BrokenPipeError): nobody waits
        os._exit(0)
    while True:
        try:
            fn, args, version, blob = conn.recv()
        except (EOFError, OSError):
            os._exit(0)  # the parent closed the pipe: nobody will ask again
        started = time.monotonic()
        _RETIRE[0] = False
        try:
            if blob is not None:
                _WORLD.update(version=None, threats=(), fields={})  # the old field goes before the new loads
                _WORLD.update(version=version, threats=pickle.loads(blob))
            value = fn(*args)
            reply: tuple[str, Any, float, bool] = ("done", value, time.monotonic() - started, _RETIRE[0])
        except MemoryError:
            reply = ("memory", "the worker's memory limit was reached", time.monotonic() - started, True)
        except Exception:
            reply = ("error", traceback.format_exc(limit=4), time.monotonic() - started, _RETIRE[0])
        try:
            conn.send(reply)
        except MemoryError:
            reply = (
                "memory",
                "the reply did not fit the worker's memory limit",
                time.monotonic() - started,
                True,
            )
            conn.send(reply)
        except (OSError, ValueError):
            os._exit(0)
        if reply[3]:
            os._exit(0)  # the parent replaces this worker: its heap (or numba's state) may be left damaged


def _limit_address_space(memory_mb: float) -> None:
    """``RLIMIT_AS``: the worker's size now (warm, numba's and llvm's reservations included) plus ``memory_mb``."""
    import resource

    size = 0
    with contextlib.suppress(OSError), open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                size = int(line.split()[1]) * 1024
    if size:
        limit = size + int(memory_mb * 1024 * 1024)
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(ORPHAN_POLL_S)
    os._exit(0)  # the planner is gone: nobody will ask this worker anything again
