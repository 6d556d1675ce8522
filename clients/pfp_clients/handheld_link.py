"""The handheld's I/O: its Zenoh session and the NMEA reader thread, both feeding one queue.

Zenoh callbacks and the reader thread only decode and enqueue (``Inbound``
items on a bounded ``queue.Queue`` with ``put_nowait``), so nothing ever
blocks Zenoh's receive path; the Textual app drains the queue on a timer.
``open_link`` opens a client-mode session and closes it on the way out.
"""

from __future__ import annotations

import os
import queue
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from typing import IO, Any

import zenoh

from pfp_clients.nmea import Fix, LocalFrame, read_sentence
from pfp_service.errors import InputError
from pfp_service.service.config import client_zenoh_config
from pfp_service.wire import Direction, Goal, UnitState, decode_direction, encode, keys, zenoh_encoding

__all__ = [
    "DirectionIn",
    "FixIn",
    "Inbound",
    "Link",
    "NmeaEnded",
    "NmeaReader",
    "NmeaRejected",
    "NoFixIn",
    "WireRejected",
    "client_config",
    "open_link",
    "open_nmea",
]

INBOX_DEPTH = 1024


@dataclass(frozen=True, slots=True)
class DirectionIn:
    direction: Direction


@dataclass(frozen=True, slots=True)
class WireRejected:
    reason: str


@dataclass(frozen=True, slots=True)
class FixIn:
    x_m: float
    y_m: float


@dataclass(frozen=True, slots=True)
class NoFixIn:
    pass


@dataclass(frozen=True, slots=True)
class NmeaRejected:
    reason: str


@dataclass(frozen=True, slots=True)
class NmeaEnded:
    reason: str


Inbound = DirectionIn | WireRejected | FixIn | NoFixIn | NmeaRejected | NmeaEnded


def _offer(inbox: queue.Queue[Inbound], item: Inbound) -> None:
    """Enqueue without ever blocking; when the UI has fallen this far behind, drop."""
    with suppress(queue.Full):
        inbox.put_nowait(item)


def client_config(endpoints: list[str]) -> zenoh.Config:
    """A client-mode config that connects to ``endpoints`` only (no multicast scouting)."""
    return client_zenoh_config(endpoints)


class Link:
    """One unit's side of the wire: state out, directions in, a liveliness token while open."""

    def __init__(self, session: zenoh.Session, mission: str, unit: str) -> None:
        self.session = session
        self.mission = mission
        self.unit = unit
        self.inbox: queue.Queue[Inbound] = queue.Queue(INBOX_DEPTH)
        self._state_pub = session.declare_publisher(
            keys.unit_state(mission, unit),
            encoding=zenoh_encoding(),
            congestion_control=zenoh.CongestionControl.DROP,
            express=True,
        )
        self._sub = session.declare_subscriber(keys.unit_direction(mission, unit), self._on_direction)
        self._token = session.liveliness().declare_token(keys.alive_unit(mission, unit))

    def _on_direction(self, sample: zenoh.Sample) -> None:
        # decode and enqueue only: this runs on Zenoh's callback thread
        try:
            d = decode_direction(sample.payload.to_bytes())
        except InputError as exc:
            _offer(self.inbox, WireRejected(str(exc)))
            return
        except Exception as exc:  # never let a surprise kill the subscriber silently
            _offer(self.inbox, WireRejected(f"{type(exc).__name__}: {exc}"))
            return
        if d.unit != self.unit:
            _offer(self.inbox, WireRejected(f"$.unit: direction for {d.unit!r}, not {self.unit!r}"))
            return
        _offer(self.inbox, DirectionIn(d))

    def publish_state(self, state: UnitState) -> None:
        """Put ``unit/{u}/state`` (drops rather than waits under congestion)."""
        self._state_pub.put(encode(state))

    def put_goal(self, goal: Goal) -> None:
        """Put ``unit/{u}/goal``."""
        self.session.put(keys.unit_goal(self.mission, self.unit), encode(goal), encoding=zenoh_encoding())

    def close(self) -> None:
        """Withdraw the token, undeclare, then close the session."""
        for entity in (self._token, self._sub, self._state_pub):
            with suppress(Exception):  # already gone with the session; closing matters more
                entity.undeclare()
        self.session.close()


@contextmanager
def open_link(endpoints: list[str], mission: str, unit: str) -> Iterator[Link]:
    """Open a client session to ``endpoints`` and the unit's link; close both on exit.

    Raises:
        InputError: ``--connect``, when no router answers (client mode fails at once).
    """
    keys.check_chunk(mission, "--mission")
    keys.check_chunk(unit, "--unit")
    try:
        session = zenoh.open(client_config(endpoints))
    except Exception as exc:
        raise InputError("--connect", f"cannot reach {', '.join(endpoints)}: {exc}") from exc
    try:
        link = Link(session, mission, unit)
    except BaseException:
        session.close()
        raise
    try:
        yield link
    finally:
        link.close()


class NmeaReader(threading.Thread):
    """Reads NMEA lines from a byte stream, converts GGA fixes to local metres, enqueues them."""

    def __init__(self, stream: IO[bytes], frame: LocalFrame, inbox: queue.Queue[Inbound]) -> None:
        super().__init__(name="nmea-reader", daemon=True)  # a blocked read must not hold up exit
        self.stream = stream
        self.frame = frame
        self.inbox = inbox

    def run(self) -> None:
        try:
            for raw in self.stream:
                self.feed(raw.decode("ascii", "replace"))
        except Exception as exc:  # a serial device unplugged, say
            _offer(self.inbox, NmeaEnded(f"read failed: {exc}"))
            return
        _offer(self.inbox, NmeaEnded("stream ended"))

    def feed(self, line: str) -> None:
        """Handle one line (public so it can be fed without a thread)."""
        try:
            result = read_sentence(line)
        except InputError as exc:
            _offer(self.inbox, NmeaRejected(str(exc)))
            return
        if result is None:
            _offer(self.inbox, NoFixIn())
        elif isinstance(result, Fix):
            x, y = self.frame.to_local_m(result.lat_deg, result.lon_deg)
            _offer(self.inbox, FixIn(x, y))


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
        return os.fdopen(pipe_fd, "rb", buffering=0)
    try:
        stream = open(path, "rb", buffering=0)  # noqa: SIM115 - the reader thread owns it
    except OSError as exc:
        raise InputError("--nmea", f"cannot open {path!r}: {exc.strerror}") from exc
    if baud is not None:
        if not os.isatty(stream.fileno()):
            stream.close()
            raise InputError("--nmea-baud", f"{path!r} is not a serial device")
        _set_baud(stream.fileno(), baud)
    return stream
