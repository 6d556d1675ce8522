"""Splitting a CoT byte stream into ``<event>`` documents, in bounded memory, sans-I/O.

A TCP or TLS link to a TAK server carries one XML document after another with
no length prefix.  pytak reads it with ``StreamReader.readuntil(b"</event>")``,
whose 64 KiB limit turns one large event into a dropped link; a TAK server
keeps such a marker and replays it on every connection, so the link never
comes back.  ``EventFramer`` instead keeps at most ``max_event_bytes`` of an
event: a longer one is skipped up to its ``</event>``, counted, and the events
after it come through.

Rules (as h11 keeps its rules in one place):
- bytes outside an event (XML declarations, whitespace, garbage) are discarded;
- an event starts at ``<event`` followed by whitespace, ``>`` or ``/``, and
  ends at the first ``</event>`` after it, or at its own ``/>``;
- memory held is at most ``max_event_bytes`` plus one chunk, whatever arrives;
- a skipped event is reported once its end has come, with its size.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["EventFramer", "Framed"]

_START = b"<event"
_END = b"</event>"
_KEEP = len(_END) - 1  # a tail this long may be the start of a split marker


@dataclass(frozen=True, slots=True)
class Framed:
    """What one ``feed`` produced: whole events (each at most the limit), and the skipped ones' sizes.

    An event too large is counted in ``skipped_bytes`` once its end has come
    (its size, ``<event`` to ``</event>``); until then the framer is skipping it.
    """

    events: list[bytes]
    skipped_bytes: list[int]

    @property
    def skipped(self) -> int:
        return len(self.skipped_bytes)


def _find_start(buf: bytearray, start: int = 0) -> int:
    while (i := buf.find(_START, start)) >= 0:
        nxt = buf[i + len(_START) : i + len(_START) + 1]
        if nxt == b"" or nxt in (b" ", b"\t", b"\r", b"\n", b">", b"/"):
            return i  # b"": not known yet; the caller keeps it and looks again with more
        start = i + 1
    return -1


class EventFramer:
    """Feed it bytes as they arrive; it returns the complete events, skipping any over the limit.

    Args:
        max_event_bytes: the largest event kept, ``<event`` to ``</event>`` inclusive.
    """

    def __init__(self, max_event_bytes: int) -> None:
        if max_event_bytes < 64:
            raise ValueError("max_event_bytes: must be at least 64")
        self.max_event_bytes = max_event_bytes
        self._buf = bytearray()
        self._skipping = False  # inside an event that is too large: discard until its end
        self._skip_size = 0  # bytes of it discarded so far
        self.skipped = 0  # events skipped since this framer was made

    @property
    def buffered(self) -> int:
        """Bytes held now (always at most ``max_event_bytes`` plus one chunk)."""
        return len(self._buf)

    def feed(self, data: bytes) -> Framed:
        """Take the next bytes of the stream; return the events they completed."""
        buf = self._buf
        buf += data
        events: list[bytes] = []
        skipped: list[int] = []
        while True:
            if self._skipping:
                end = buf.find(_END)
                if end < 0:
                    drop = max(0, len(buf) - _KEEP)
                    self._skip_size += drop
                    del buf[:drop]
                    break
                skipped.append(self._skip_size + end + len(_END))
                del buf[: end + len(_END)]
                self._skipping = False
                continue
            start = _find_start(buf)
            if start < 0:
                del buf[: max(0, len(buf) - len(_START))]  # keep what may be a split "<event"
                break
            del buf[:start]
            if len(buf) <= len(_START):
                break  # "<event" and nothing after it yet
            end = buf.find(_END)
            close = buf.find(b">")
            if close > 0 and buf[close - 1 : close] == b"/" and (end < 0 or close < end):
                end, size = close, close + 1  # <event .../>: empty, and complete
            else:
                size = end + len(_END)
            if end < 0:
                if len(buf) > self.max_event_bytes:
                    self._skipping = True
                    self._skip_size = len(buf) - _KEEP
                    del buf[: self._skip_size]
                    continue
                break
            if size <= self.max_event_bytes:
                events.append(bytes(buf[:size]))
            else:
                skipped.append(size)  # it all came in one chunk: over the limit all the same
            del buf[:size]
        self.skipped += len(skipped)
        return Framed(events, skipped)
