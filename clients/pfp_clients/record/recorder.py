"""``pfp record``: every key of a mission into an MCAP file, until stopped.

One subscriber on ``mumt/{m}/**`` with a FIFO channel (``FIFO_DEPTH``
samples held by Zenoh, no Python on the receive path) and liveliness
subscribers on the mission's tokens; one loop drains them into the file every
``DRAIN_EVERY_S`` and reports the largest batch it ever drained.  A sample's
log time is the router's timestamp of it (the planner is the router; when a
sample has none, the time it was drained).  SIGTERM or SIGINT (the ``stop``
event) ends the subscriptions, the writer drains what is left and the file is
finished (summary, index, CRCs), so a stopped recording is a whole file.

The planner's origin is asked once at the start (its status) and written in
the file's metadata, so ``pfp report`` can give lat/lon and GeoJSON.  The
planners' ``msgs_out`` is asked again once the subscriptions are in place and
when the recording stops, and what the record missed of it goes into the
metadata ``pfp.coverage`` (``coverage.py``): a recording says what it lacks.
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

from pfp_clients.record.coverage import Counted, Coverage
from pfp_clients.record.mcapfile import MissionWriter
from pfp_service.errors import InputError
from pfp_service.wire import keys

__all__ = ["RecordStats", "record"]

_ALIVE, _GONE = 2, 3
DRAIN_EVERY_S = 0.02
FIFO_DEPTH = 1_000_000  # samples Zenoh may hold for the writer: 100 s of 1,000 units x 10 Hz
SETTLE_S = 0.5  # after the last status answer, what was published before it still arrives


def _counted(session: Any, mission: str, timeout_s: float = 2.0) -> Counted:
    """Every planner's ``msgs_out`` now (none: no planner answered)."""
    from pfp_service.errors import InputError
    from pfp_service.wire import decode_planner_status

    asked = time.time_ns()
    out: dict[tuple[str, str], int] = {}
    for reply in session.get(keys.planner_statuses(mission), timeout=timeout_s):
        if reply.ok is None:
            continue
        try:
            st = decode_planner_status(reply.ok.payload.to_bytes())
        except InputError:
            continue
        out[(st.planner, st.session)] = st.msgs_out
    return Counted(out, asked, time.time_ns())


def _when(sample: Any) -> int:
    """When the router took the sample (its timestamp), else now; nanoseconds since the UNIX epoch."""
    ts = sample.timestamp
    if ts is None:
        return time.time_ns()
    return int(ts.get_time_as_ntp64().as_nanos())


@dataclass
class RecordStats:
    """What a recording took: messages by kind, the largest batch drained at once, the process's CPU and the file."""

    messages: int = 0
    by_kind: dict[str, int] = field(default_factory=dict)
    max_backlog: int = 0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    bytes: int = 0
    coverage: dict[str, Any] = field(default_factory=dict)


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
    tokens: collections.deque[tuple[int, int, str, bytes]] = collections.deque()

    def on_token(sample: zenoh.Sample) -> None:  # enqueue only (tokens are few)
        kind = _ALIVE if sample.kind == zenoh.SampleKind.PUT else _GONE
        tokens.append((kind, time.time_ns(), str(sample.key_expr), b""))

    started = time.time_ns()
    answered, origin = False, None
    ask_until = time.monotonic() + origin_wait_s
    while not answered and not stop.is_set():  # a session just opened may not route a query yet
        answered, origin = planner_origin(session, m, 0.5)
        if time.monotonic() >= ask_until:
            break
        if not answered:
            stop.wait(0.2)
    stats = RecordStats()
    cpu0 = time.process_time()  # the whole process: zenoh's threads and the callbacks too
    with contextlib.closing(stream):
        writer = MissionWriter(stream, m, origin, started)
        # a FIFO channel, not a callback: samples wait in Zenoh's own queue and no Python runs on the
        # receive path, so a busy writer never holds up the socket (with a callback, at 1,000 units
        # x 10 Hz, the router dropped 0.2 % of the directions meant for this session)
        data_sub = session.declare_subscriber(keys.mission_all(m), zenoh.handlers.FifoChannel(FIFO_DEPTH))
        subs = [
            data_sub,
            session.liveliness().declare_subscriber(keys.alive_units(m), on_token, history=True),
            session.liveliness().declare_subscriber(keys.alive_planners(m), on_token, history=True),
        ]
        coverage = Coverage()
        coverage.begin(_counted(session, m))  # nothing drained yet: every sample is counted after it
        # said once the subscribers are declared and a query has gone to the router and back after
        # them (``_counted``): whatever a member puts after reading this line is in the record
        say(
            f"pfp record: mission {m!r} into {out}"
            + (f", origin {origin.lat:g},{origin.lon:g}" if origin is not None else "")
            + ("" if answered else " (no planner answered yet: no origin in the record)")
        )

        def drain() -> int:
            n = 0
            while (sample := data_sub.try_recv()) is not None:
                n += 1
                t_ns = _when(sample)
                if sample.kind == zenoh.SampleKind.PUT:
                    coverage.seen(writer.put(str(sample.key_expr), sample.payload.to_bytes(), t_ns), t_ns)
                else:
                    writer.delete(str(sample.key_expr), t_ns)
            while tokens:
                kind, t_ns, key, _ = tokens.popleft()
                writer.alive(key, kind == _ALIVE, t_ns)
            return n

        try:
            while not stop.is_set():
                stats.max_backlog = max(stats.max_backlog, drain())
                # drained: sleep a little rather than poll (the FIFO holds what comes meanwhile)
                stop.wait(DRAIN_EVERY_S)
            stats.max_backlog = max(stats.max_backlog, drain())
            coverage.end(_counted(session, m))
            settle_until = time.monotonic() + SETTLE_S
            while time.monotonic() < settle_until:  # what was published before the answer still comes
                drain()
                time.sleep(DRAIN_EVERY_S)
        finally:
            for s in subs[1:]:
                with contextlib.suppress(Exception):  # gone with the session
                    s.undeclare()
            with contextlib.suppress(Exception):
                drain()  # what came before the stop
                data_sub.undeclare()
            stats.coverage = coverage.result()
            writer.coverage(stats.coverage)
            writer.finish()
    stats.messages = writer.count
    stats.by_kind = dict(writer.by_kind)
    stats.wall_s = (time.time_ns() - started) / 1e9
    stats.cpu_s = time.process_time() - cpu0
    stats.bytes = out.stat().st_size
    return stats
