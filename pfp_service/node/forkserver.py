"""Starting a worker process cheaply: the fork server (``ForkServer``) and the workers it forks (``Forked``).

``run`` forks the fork server from the warm planner before its Zenoh session opens and installs it
(``install_fork_server``); every ``workers.WorkerPool`` made afterwards asks it for its workers,
and starts fresh interpreters where there is none or it has gone.  Apart from the pool because
it is how a process starts, not how tasks are run.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import socket
import subprocess
import threading

from pfp_service.node.log import get_logger
from pfp_service.node.workerproc import serve_forks

__all__ = ["ForkServer", "Forked", "install_fork_server", "installed_fork_server"]

log = get_logger("workers")  # the pool's log: a fork server gone is the pool's news


class ForkServer:
    """A fork server: a copy of the warm planner, forked before any thread or Zenoh session, that forks workers.

    ``start`` forks it from the planner once the heavy libraries are imported
    and the numba kernels loaded (``previews.warm_up``), and only while the process
    has no other Python thread (forking a process with Zenoh's threads is
    unsafe; OpenBLAS stops its own pool around a fork).  Each worker is then a
    fork of the fork server: it shares the loaded libraries, the compiled kernels
    and the interpreter's heap copy-on-write with the fork server, its siblings and
    the planner, so it costs only the pages it writes, and starts in
    milliseconds instead of seconds.  The caller should ``gc.freeze()`` first,
    so the collector's passes in any of them do not write (and so copy) every
    object's header.

    A worker's socket end comes to the fork server by ``send_fds``; its process id
    comes back.  A worker is not the planner's child: the pool watches and
    kills it through a pidfd (``Forked``).  Every worker and the fork server hold the
    read end of a lifeline pipe whose only write end is the planner's, so the
    moment the planner dies, even by ``SIGKILL``, each of them reads its end
    of file and exits.
    """

    def __init__(self, pid: int, sock: socket.socket, lifeline: int) -> None:
        self.pid = pid
        self._sock = sock
        self._lifeline = lifeline
        self._lock = threading.Lock()
        self._dead = False

    @classmethod
    def start(cls) -> ForkServer | None:
        """Fork the fork server from this process; ``None`` where it would be unsafe (other threads) or unsupported."""
        if threading.active_count() > 1 or not hasattr(os, "pidfd_open") or not hasattr(socket, "send_fds"):
            return None
        ours, theirs = socket.socketpair()
        life_r, life_w = os.pipe()
        try:
            pid = os.fork()
        except OSError:
            for fd in (life_r, life_w):
                os.close(fd)
            ours.close()
            theirs.close()
            return None
        if pid == 0:  # the fork server: it never returns into the planner's code
            code = 1
            try:
                ours.close()
                os.close(life_w)
                serve_forks(theirs, life_r)
                code = 0
            finally:
                os._exit(code)
        theirs.close()
        os.close(life_r)
        return cls(pid, ours, life_w)

    def spawn(self, fd: int, memory_mb: float | None, nice: int) -> Forked | None:
        """A worker forked by the fork server on the socket end ``fd``; ``None`` if the fork server is gone."""
        with self._lock:
            if self._dead:
                return None
            try:
                socket.send_fds(self._sock, [json.dumps([memory_mb, nice]).encode()], [fd])
                reply = self._sock.recv(32)
            except OSError:
                reply = b""
            if not reply:  # the fork server died (the OOM killer, say): the pool starts fresh interpreters
                self._dead = True
                log.warning("the worker fork server is gone; workers start as new interpreters")
                return None
        try:
            return Forked(int(reply))
        except (ValueError, OSError):  # the worker is already gone: its start failed
            return None

    def close(self) -> None:
        """Stop the fork server (its workers stop with their pools, or with the planner)."""
        with self._lock:
            self._dead = True
            with contextlib.suppress(OSError):
                self._sock.close()
            with contextlib.suppress(OSError):
                os.close(self._lifeline)
            with contextlib.suppress(OSError):
                os.kill(self.pid, signal.SIGKILL)
            with contextlib.suppress(OSError):
                os.waitpid(self.pid, 0)


_FORK_SERVER: list[ForkServer | None] = [None]


def install_fork_server(server: ForkServer | None) -> None:
    """Pools made from now on fork their workers from ``server`` (``None``: fresh interpreters again)."""
    _FORK_SERVER[0] = server


def installed_fork_server() -> ForkServer | None:
    """The fork server a pool made now forks its workers from (``None``: fresh interpreters)."""
    return _FORK_SERVER[0]


class Forked:
    """A worker the fork server forked (not our child): ``subprocess.Popen``'s ``poll``/``kill``/``wait``, on a pidfd."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self._fd: int | None = os.pidfd_open(pid)
        self._lock = threading.Lock()
        self.returncode: int | None = None

    def poll(self) -> int | None:
        return self._wait(0.0)

    def wait(self, timeout: float | None = None) -> int:
        code = self._wait(timeout)
        if code is None:
            raise subprocess.TimeoutExpired(f"worker {self.pid}", timeout or 0.0)
        return code

    def _wait(self, timeout: float | None) -> int | None:
        with self._lock:
            fd = self._fd
        if fd is None:
            return self.returncode
        with contextlib.suppress(OSError, ValueError):
            if not select.select([fd], [], [], timeout)[0]:
                return None
        with self._lock:
            if self._fd is not None:
                os.close(self._fd)
                self._fd = None
                self.returncode = -1  # gone; its status went to the fork server, which reaps it
        return self.returncode

    def kill(self) -> None:
        with self._lock:
            if self._fd is not None:
                with contextlib.suppress(OSError):
                    signal.pidfd_send_signal(self._fd, signal.SIGKILL)
