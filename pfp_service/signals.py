"""How a long-running command stops: SIGTERM and SIGINT end it cleanly, and its exit code says which came.

A supervisor (``kill``, systemd, ``docker stop``) sends SIGTERM to the
process: the command was asked to stop and did, so it exits 0.  A terminal's
Ctrl-C sends SIGINT to the whole process group: the command was interrupted,
so it exits 130 (128 + 2, what a shell reports for an interrupted program).
Either way the command first closes what it opened (sessions, tokens,
subscribers) and prints no traceback.

``SignalStop`` turns both signals into one ``threading.Event`` the command's
loop already watches, and remembers the first signal for ``exit_code``.  A
second signal while the command is closing changes nothing: closing a Zenoh
session half-way can hang the interpreter at exit, which is worse than waiting.

    with SignalStop() as stop:
        code = run_until(stop.event)
    return stop.exit_code(code)

A command that spends its time in compiled kernels (``pfp plan --planner
optimal``) has no loop to watch an event: ``interruptible(work)`` runs the
work on a thread and ends the process with 130 on Ctrl-C.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any, NoReturn, TypeVar

__all__ = ["EXIT_CODES", "SIGNALS", "SignalStop", "interruptible", "leave_now", "settle_callback_threads"]

_T = TypeVar("_T")
WAIT_SLICE_S = 0.1  # the main thread waits on the work in slices this long (a signal is seen within it)

SIGNALS = (signal.SIGTERM, signal.SIGINT)
EXIT_CODES = {signal.SIGTERM: 0, signal.SIGINT: 130}


class SignalStop:
    """SIGTERM and SIGINT set ``event`` while in the ``with`` block; the first one sets the exit code.

    Off the main thread (a program embedding a command) no handler can be
    installed: the block runs with the handlers it found, and only ``event``
    (set by the caller) or ``note()`` stops it.

    Args:
        event: the event to set; a new one if not given.
    """

    def __init__(self, event: threading.Event | None = None) -> None:
        self.event = event or threading.Event()
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> SignalStop:
        self.install()
        return self

    def install(self) -> None:
        """(Re)install the handlers, e.g. after an asyncio loop that replaced them has closed."""
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNALS:
                previous = signal.signal(sig, self._handle)
                self._previous.setdefault(sig, previous)

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()

    def _handle(self, signum: int, _frame: FrameType | None) -> None:
        self.note(signum)

    def note(self, signum: int) -> None:
        """Record ``signum`` (the first one wins) and set the event: for handlers installed elsewhere,
        such as an asyncio loop's ``add_signal_handler``."""
        if self.signum is None:
            self.signum = int(signum)
        self.event.set()

    @property
    def signalled(self) -> bool:
        return self.signum is not None

    def exit_code(self, code: int) -> int:
        """0 after SIGTERM, 130 after SIGINT, else ``code`` (how the command ended on its own)."""
        if self.signum is None:
            return code
        return EXIT_CODES.get(signal.Signals(self.signum), code)


def leave_now(code: int) -> NoReturn:
    """Flush the output and end the process with ``code``, without finalising the interpreter.

    For a process with a thread that cannot be stopped (a compiled kernel, a
    ``zenoh.open`` in progress): finalising under it is not safe.
    """
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):  # a closed pipe: nothing left to say
            stream.flush()
    os._exit(code)


ZENOH_CALLBACK_THREAD = "(pyo3-closure)"  # how the thread zenoh-python starts for a Python callback is named
SETTLE_WITHIN_S = 3.0


def settle_callback_threads(within_s: float = SETTLE_WITHIN_S) -> bool:
    """Wait (at most ``within_s``) for the threads Zenoh started to run Python callbacks; whether all ended.

    zenoh-python runs a subscriber's or queryable's plain callable on a
    ``threading.Thread`` it starts, which inherits the daemon flag of the
    thread that declared it.  Closing the session ends those threads, but
    each must take the GIL once more to return.  A daemon one that does so
    while the interpreter finalises is ended inside Rust frames, and the
    process aborts ("FATAL: exception not rethrown", exit -6): 13 of 40 runs
    of a script that declared 20 subscribers on a daemon thread, closed the
    session and returned.  A non-daemon one whose session was never closed
    holds the interpreter at exit for ever.  So a command's process waits here
    before it finalises, and leaves with ``leave_now`` when one is still alive.
    """
    deadline = time.monotonic() + within_s
    me = threading.current_thread()
    for thread in threading.enumerate():
        if thread is not me and thread.name.endswith(ZENOH_CALLBACK_THREAD):
            thread.join(max(0.0, deadline - time.monotonic()))
    return not any(t.name.endswith(ZENOH_CALLBACK_THREAD) and t.is_alive() for t in threading.enumerate())


def interruptible(work: Callable[[], _T]) -> _T:
    """``work()``, on a worker thread while the main thread waits; Ctrl-C ends the process with 130 at once.

    Python handles a signal on the main thread, at the next bytecode it runs.
    While the main thread runs compiled kernels that point can fall inside
    the boxing of a kernel's result, and the ``KeyboardInterrupt`` raised
    there crashed the process: ``pfp plan --planner optimal --cells 2000``
    interrupted 1.5-2.5 s in died of SIGSEGV in 4 of 7 runs (faulthandler:
    in the grid's edge kernel).  Here the kernels run on a thread no signal
    is delivered to, and the main thread only waits.  The work cannot be
    stopped mid-kernel, and finalising the interpreter under a running
    thread is not safe either, so on SIGINT the process flushes its output
    and leaves with ``os._exit(130)``: no traceback, no core.  Off the main
    thread (a program embedding a command) ``work`` just runs.

    Raises:
        whatever ``work`` raised, on the calling thread.
    """
    if threading.current_thread() is not threading.main_thread():
        return work()
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = work()
        except BaseException as exc:  # handed to the waiting thread
            box["error"] = exc

    worker = threading.Thread(target=run, name="pfp-work", daemon=True)
    worker.start()
    try:
        while worker.is_alive():
            worker.join(WAIT_SLICE_S)
    except KeyboardInterrupt:
        leave_now(EXIT_CODES[signal.SIGINT])
    if "error" in box:
        raise box["error"]
    return box["value"]  # type: ignore[no-any-return]
