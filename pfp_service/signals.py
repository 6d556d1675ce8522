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
"""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any

__all__ = ["EXIT_CODES", "SIGNALS", "SignalStop"]

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
