"""NMEA from a GPS receiver, a log or a pipe, into the handheld's inbox: ``NmeaReader`` and ``open_nmea``.

Each GGA fix becomes local metres (``nmea.LocalFrame``) and a ``FixIn`` on the same inbox the
planner's link (``handheld_link``) feeds; a log file is replayed at its fixes' pace.  Apart from
the link because it is the receiver's side of the handheld, not the planner's.
"""

from __future__ import annotations

import os
import queue
import stat
import sys
import threading
from collections.abc import Iterator
from typing import IO, Any

from pfp_clients.handheld_link import FixIn, Inbound, NmeaEnded, NmeaRejected, NoFixIn, offer
from pfp_clients.nmea import IGNORED, Fix, LocalFrame, read_sentence
from pfp_service.errors import InputError

__all__ = ["MAX_BAD_RUN", "MAX_GAP_S", "MAX_LINE_BYTES", "NmeaReader", "is_regular_file", "open_nmea"]

MAX_LINE_BYTES = 256  # NMEA caps a sentence at 82 characters; anything past this is not one
MAX_BAD_RUN = 1000  # this many lines in a row that are not sentences: not a GPS receiver at all
MAX_GAP_S = 10.0  # a longer jump between two fixes' UTC times is a gap in the log, not a pause to replay


def is_regular_file(stream: IO[bytes]) -> bool:
    """True for a file on disk (a log to replay), False for a device, pipe or terminal (live)."""
    try:
        return stat.S_ISREG(os.fstat(stream.fileno()).st_mode)
    except (OSError, ValueError):
        return False


class NmeaReader(threading.Thread):
    """Reads NMEA lines from a byte stream, converts GGA fixes to local metres, enqueues them.

    Args:
        stream: the byte stream (a file, a serial device, a pipe).
        frame: the local frame fixes are converted to.
        inbox: where items go.
        rate_hz: replay GGA sentences at this rate.
        paced: replay by the fixes' UTC times (default: when ``stream`` is a regular file,
            which would otherwise be read in one burst).
    """

    def __init__(
        self,
        stream: IO[bytes],
        frame: LocalFrame,
        inbox: queue.Queue[Inbound],
        rate_hz: float | None = None,
        paced: bool | None = None,
    ) -> None:
        super().__init__(name="nmea-reader", daemon=True)  # a blocked read must not hold up exit
        self.stream = stream
        self.frame = frame
        self.inbox = inbox
        self.rate_hz = rate_hz
        self.paced = is_regular_file(stream) if paced is None else paced
        self.bad_run = 0
        self._stop_event = threading.Event()
        self._last_utc_s: float | None = None

    def stop(self) -> None:
        """End the replay at the next line (a blocked device read still ends with the process)."""
        self._stop_event.set()

    def _lines(self) -> Iterator[bytes | None]:
        """Lines of at most ``MAX_LINE_BYTES``; ``None`` for a longer one (the rest is skipped)."""
        while not self._stop_event.is_set():
            raw = self.stream.readline(MAX_LINE_BYTES + 1)
            if not raw:
                return
            if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                while (rest := self.stream.readline(64 * 1024)) and not rest.endswith(b"\n"):
                    pass
                yield None
                continue
            yield raw

    def run(self) -> None:
        try:
            for raw in self._lines():
                if raw is None:
                    self._rejected(f"line longer than {MAX_LINE_BYTES} bytes")
                else:
                    self.feed(raw.decode("ascii", "replace"))
                if self.bad_run >= MAX_BAD_RUN:
                    offer(self.inbox, NmeaEnded(f"not NMEA: {self.bad_run} lines in a row were no sentence"))
                    return
        except OSError as exc:  # a serial device unplugged, say
            offer(self.inbox, NmeaEnded(f"read failed: {exc.strerror or exc}"))
            return
        offer(self.inbox, NmeaEnded("stream ended"))

    def _rejected(self, reason: str) -> None:
        self.bad_run += 1
        offer(self.inbox, NmeaRejected(reason))

    def _pace(self, fix: Fix | None) -> None:
        """Wait as long as the recording did between this GGA sentence and the last."""
        if self.rate_hz is not None:
            self._stop_event.wait(1.0 / self.rate_hz)
            return
        if not self.paced or fix is None or fix.utc_s is None:
            return
        last, self._last_utc_s = self._last_utc_s, fix.utc_s
        if last is not None:
            gap = (fix.utc_s - last) % 86_400.0  # across midnight
            if 0.0 < gap <= MAX_GAP_S:
                self._stop_event.wait(gap)

    def feed(self, line: str) -> None:
        """Handle one line (public so it can be fed without a thread)."""
        try:
            result = read_sentence(line)
        except InputError as exc:
            self._rejected(str(exc))
            return
        if result == IGNORED:
            return
        self.bad_run = 0
        fix = result if isinstance(result, Fix) else None
        self._pace(fix)
        if fix is None:
            offer(self.inbox, NoFixIn())
        else:
            x, y = self.frame.to_local_m(fix.lat_deg, fix.lon_deg)
            offer(self.inbox, FixIn(x, y))


def _set_baud(fd: int, baud: int) -> None:
    import termios
    import tty

    speed = getattr(termios, f"B{baud}", None)
    if speed is None:
        raise InputError("--nmea-baud", f"{baud} is not a baud rate this system knows")
    tty.setraw(fd)
    attrs: list[Any] = termios.tcgetattr(fd)
    attrs[4] = attrs[5] = speed
    termios.tcsetattr(fd, termios.TCSANOW, attrs)


def open_nmea(path: str, baud: int | None = None) -> IO[bytes]:
    """Open the NMEA source: a file or serial device, or ``-`` for stdin.

    With ``-`` and a pipe on stdin, the pipe is moved to a new descriptor and the
    terminal (``/dev/tty``) takes its place as fd 0, where Textual reads keys.

    Raises:
        InputError: ``--nmea``, when it cannot be opened (or stdin has no terminal behind it).
    """
    if path == "-":
        if sys.stdin is None or os.isatty(0):
            raise InputError("--nmea", "'-' needs the sentences piped into stdin")
        try:
            tty_fd = os.open("/dev/tty", os.O_RDWR)
        except OSError as exc:
            raise InputError("--nmea", f"'-' needs a terminal for the keyboard: {exc}") from exc
        pipe_fd = os.dup(0)
        os.dup2(tty_fd, 0)
        os.close(tty_fd)
        return os.fdopen(pipe_fd, "rb")  # buffered: readline() then costs one read per chunk, not per byte
    try:
        stream = open(path, "rb")  # noqa: SIM115 - the reader thread owns it
    except OSError as exc:
        raise InputError("--nmea", f"cannot open {path!r}: {exc.strerror}") from exc
    if baud is not None:
        if not os.isatty(stream.fileno()):
            stream.close()
            raise InputError("--nmea-baud", f"{path!r} is not a serial device")
        _set_baud(stream.fileno(), baud)
    return stream
