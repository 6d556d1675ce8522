"""``pfp record``: every key of a mission into an MCAP file, until stopped.

One subscriber on ``mumt/{m}/**`` and one liveliness subscriber on the
mission's tokens.  Their callbacks decode nothing: they append the key, the
payload and the receipt time to a deque (append is atomic under the GIL, and
costs a callback about a microsecond), and one writer thread drains it into
the file.  Nothing is dropped on purpose: the deque is unbounded, and the
writer reports how far behind it ever fell.  SIGTERM or SIGINT (the ``stop``
event) ends the subscriptions, the writer drains what is left and the file is
finished (summary, index, CRCs), so a stopped recording is a whole file.

The planner's origin is asked once at the start (its status) and written in
the file's metadata, so ``pfp report`` can give lat/lon and GeoJSON.
"""

from __future__ import annotations

import collections
import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pfp_clients.record.mcapfile import MissionWriter
from pfp_service.errors import InputError
from pfp_service.wire import keys

__all__ = ["RecordStats", "record"]

_PUT, _DELETE, _ALIVE, _GONE = 0, 1, 2, 3


@dataclass
class RecordStats:
    """What a recording took: messages by kind, the deepest backlog, the process's CPU and the file."""

    messages: int = 0
    by_kind: dict[str, int] = field(default_factory=dict)
    max_backlog: int = 0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    bytes: int = 0


def record(
    session: Any,
    mission: str,
    out: Path,
    stop: threading.Event,
    say: Callable[[str], None] = print,
    origin_wait_s: float = 3.0,
) -> RecordStats:
    """Record ``mission`` on ``session`` into ``out`` until ``stop`` is set.

    Previews are not in the record: a query and its reply travel between the asker and the
    planner only, and a subscriber sees neither.

    Raises:
        InputError: ``out`` cannot be written.
    """
    import zenoh

    from pfp_clients.frames import planner_origin

    m = keys.check_chunk(mission, "--mission")
    try:
        stream = out.open("wb")
    except OSError as exc:
        raise InputError(str(out), f"cannot write: {exc.strerror or exc}") from None
    queue: collections.deque[tuple[int, int, str, bytes]] = collections.deque()
    wake = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:  # enqueue only
        if sample.kind == zenoh.SampleKind.PUT:
            queue.append((_PUT, time.time_ns(), str(sample.key_expr), sample.payload.to_bytes()))
        else:
            queue.append((_DELETE, time.time_ns(), str(sample.key_expr), b""))
        wake.set()

    def on_token(sample: zenoh.Sample) -> None:
        kind = _ALIVE if sample.kind == zenoh.SampleKind.PUT else _GONE
        queue.append((kind, time.time_ns(), str(sample.key_expr), b""))
        wake.set()

    started = time.time_ns()
    answered, origin = False, None
    ask_until = time.monotonic() + origin_wait_s
    while not answered and not stop.is_set():  # a session just opened may not route a query yet
        answered, origin = planner_origin(session, m, 0.5)
        if time.monotonic() >= ask_until:
            break
        if not answered:
            stop.wait(0.2)
    say(
        f"pfp record: mission {m!r} into {out}"
        + (f", origin {origin.lat:g},{origin.lon:g}" if origin is not None else "")
        + ("" if answered else " (no planner answered yet: no origin in the record)")
    )
    stats = RecordStats()
    cpu0 = time.process_time()  # the whole process: zenoh's threads and the callbacks too
    with contextlib.closing(stream):
        writer = MissionWriter(stream, m, origin, started)
        subs = [
            session.declare_subscriber(keys.mission_all(m), on_sample),
            session.liveliness().declare_subscriber(keys.alive_units(m), on_token, history=True),
            session.liveliness().declare_subscriber(keys.alive_planners(m), on_token, history=True),
        ]
        try:
            while True:
                stopping = stop.is_set()
                stats.max_backlog = max(stats.max_backlog, len(queue))
                while queue:
                    kind, t_ns, key, data = queue.popleft()
                    if kind == _PUT:
                        writer.put(key, data, t_ns)
                    elif kind == _DELETE:
                        writer.delete(key, t_ns)
                    else:
                        writer.alive(key, kind == _ALIVE, t_ns)
                if stopping:
                    break
                wake.wait(0.1)
                wake.clear()
        finally:
            for s in subs:
                with contextlib.suppress(Exception):  # gone with the session
                    s.undeclare()
            while queue:  # what came before the subscriptions ended
                kind, t_ns, key, data = queue.popleft()
                if kind == _PUT:
                    writer.put(key, data, t_ns)
                elif kind == _DELETE:
                    writer.delete(key, t_ns)
                else:
                    writer.alive(key, kind == _ALIVE, t_ns)
            writer.finish()
    stats.messages = writer.count
    stats.by_kind = dict(writer.by_kind)
    stats.wall_s = (time.time_ns() - started) / 1e9
    stats.cpu_s = time.process_time() - cpu0
    stats.bytes = out.stat().st_size
    return stats
