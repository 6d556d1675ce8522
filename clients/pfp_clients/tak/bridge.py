"""The bridge's I/O: TAK transports through pytak, the planner through Zenoh, one asyncio loop between.

Shape (as the zenoh examples): ``run(settings, links, zenoh_conf)`` opens the
session in ``with``, declares the subscribers, connects every TAK link and
then drains three queues until stopped:

- Zenoh callbacks only hand ``(kind, key, payload)`` to the loop
  (``call_soon_threadsafe``), never decode or publish there;
- each TAK link (a pytak ``COT_URL``: ``udp://239.2.3.1:6969`` multicast,
  ``tcp://host:8087``, ``tls://host:8089`` with ``TlsFiles``, ``+wo``/``+ro``
  for one direction only) is opened by pytak and written by pytak's TX
  worker.  A TCP/TLS stream is read by ``framing.EventFramer``, not pytak's
  RX worker: an event over ``cot.MAX_EVENT_BYTES`` is skipped and the link
  stays up (pytak's 64 KiB ``readuntil`` limit dropped it, and a server that
  keeps the event replays it on every connection).  UDP datagrams go through
  pytak's RX worker.  What is read goes through ``BridgeState.on_cot``;
- a ticker every ``TICK_S`` sends held-back and refreshed events, pictures
  due to a link, and asks for routes.

A route is the unit's live preview, queried on a worker thread with a
timeout.  A link that fails is logged and reconnected after ``RECONNECT_S``;
once up it gets the whole picture.  SIGTERM stops the bridge with exit code
0 and SIGINT with 130, after the subscribers are undeclared and the session closed.
``pytak`` is imported only here, so the rest of the package works without the ``[tak]`` extra.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import time
from collections.abc import Callable, Sequence
from configparser import ConfigParser
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pfp_clients.tak import cot, tombfile
from pfp_clients.tak.framing import EventFramer
from pfp_clients.tak.outputs import Outputs, ZenohDelete, ZenohPut
from pfp_clients.tak.state import BridgeSettings, BridgeState
from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from pfp_service.wire.delivery import Deliverer
from pfp_service.world.translate import decode_plan_result

__all__ = ["RECONNECT_S", "TICK_S", "TlsFiles", "link_config", "run"]

log = logging.getLogger("pfp.tak")
TICK_S = 0.1
RECONNECT_S = 2.0
PREVIEW_TIMEOUT_S = 2.0
READ_CHUNK = 64 * 1024
RX_BACKLOG = 10_000  # events read and not yet handled; past it the link waits (TCP backpressure)
EXIT_TERMINATED, EXIT_INTERRUPTED = 0, 130


@dataclass(frozen=True, slots=True)
class TlsFiles:
    """Client certificate, key and CA for a ``tls://`` TAK server (pytak's ``PYTAK_TLS_*``)."""

    cert: str | None = None
    key: str | None = None
    cafile: str | None = None
    dont_verify: bool = False


def link_config(url: str, tls: TlsFiles | None = None) -> Any:
    """pytak's config section for one link: XML payloads (``TAK_PROTO=0``), no FTS sleeps."""
    cfg = ConfigParser(interpolation=None)
    values = {"COT_URL": url, "TAK_PROTO": "0"}
    if tls is not None:
        for name, value in (
            ("PYTAK_TLS_CLIENT_CERT", tls.cert),
            ("PYTAK_TLS_CLIENT_KEY", tls.key),
            ("PYTAK_TLS_CLIENT_CAFILE", tls.cafile),
        ):
            if value:
                values[name] = value
        if tls.dont_verify:
            values["PYTAK_TLS_DONT_VERIFY"] = "1"
    cfg["pfp"] = values
    return cfg["pfp"]


class _Link:
    """One TAK transport: opened by pytak, read in bounded frames, reconnected when it fails."""

    def __init__(
        self,
        url: str,
        tls: TlsFiles | None,
        rx: asyncio.Queue[tuple[str, bytes]],
        on_up: Callable[[str], None] = lambda _url: None,
    ) -> None:
        self.url, self.tls, self.rx, self.on_up = url, tls, rx, on_up
        self.tx: asyncio.Queue[bytes] = asyncio.Queue(maxsize=1000)
        self.connected = asyncio.Event()
        scheme = url.split("://", 1)[0].lower()
        self.write_only, self.read_only = "+wo" in scheme, "+ro" in scheme
        self.connects = 0  # how many times it has connected
        self.skipped = 0  # events skipped as too large

    def send(self, data: bytes) -> None:
        if self.read_only or not self.connected.is_set():
            return  # nobody to tell; a link gets the whole picture once it is back
        if self.tx.full():
            self.tx.get_nowait()  # drop the oldest, as pytak does
        self.tx.put_nowait(data)

    async def run(self) -> None:
        import pytak

        while True:
            section = link_config(self.url, self.tls)
            reader = writer = None
            tasks: list[asyncio.Task[Any]] = []
            try:
                reader, writer = await pytak.protocol_factory(section)
                if writer is not None:
                    tasks.append(asyncio.create_task(pytak.TXWorker(self.tx, section, writer).run()))
                if isinstance(reader, asyncio.StreamReader):
                    tasks.append(asyncio.create_task(self._read_stream(reader)))
                elif reader is not None:
                    rx_queue: asyncio.Queue[bytes] = asyncio.Queue(maxsize=RX_BACKLOG)
                    tasks.append(asyncio.create_task(pytak.RXWorker(rx_queue, section, reader).run()))
                    tasks.append(asyncio.create_task(self._forward(rx_queue)))
                self.connects += 1
                self.connected.set()
                log.info("tak: connected %s", self.url)
                self.on_up(self.url)
                done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
                for t in done:
                    if t.exception() is not None:
                        raise t.exception()  # type: ignore[misc]
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # a TAK link's failure is logged and retried, never fatal
                log.warning("tak: link %s failed: %s; retrying in %g s", self.url, exc, RECONNECT_S)
            finally:
                self.connected.clear()
                for t in tasks:
                    t.cancel()
                for w in (writer, reader):
                    close = getattr(w, "close", None)
                    if callable(close):
                        with contextlib.suppress(
                            Exception
                        ):  # a broken transport may raise; it is gone anyway
                            close()
            await asyncio.sleep(RECONNECT_S)

    async def _read_stream(self, reader: asyncio.StreamReader) -> None:
        framer = EventFramer(cot.MAX_EVENT_BYTES)
        while True:
            chunk = await reader.read(READ_CHUNK)
            if not chunk:
                raise ConnectionError("the server closed the connection")
            framed = framer.feed(chunk)
            for size in framed.skipped_bytes:
                self.skipped += 1
                log.warning(
                    "tak: skipped a CoT event of %d bytes (over %d) from %s; the link stays up",
                    size,
                    cot.MAX_EVENT_BYTES,
                    self.url,
                )
            if self.write_only:
                continue  # drained so the server never blocks on us, and dropped
            for event in framed.events:
                await self.rx.put((self.url, event))

    async def _forward(self, rx_queue: asyncio.Queue[bytes]) -> None:
        while True:
            data = await rx_queue.get()
            await self.rx.put((self.url, data))


async def _main(
    settings: BridgeSettings,
    urls: Sequence[str],
    tls: TlsFiles | None,
    session: Any,
    stop: asyncio.Event,
    ready: asyncio.Event | None,
    tomb_path: Path | None,
) -> int:
    loop = asyncio.get_running_loop()
    state = BridgeState(settings, log=lambda text: log.warning("tak: %s", text))
    keeper = None if tomb_path is None else tombfile.Keeper(tomb_path, lambda t: log.warning("tak: %s", t))
    if keeper is not None and (kept := keeper.restore(state, time.time())):
        log.info("tak: %d tombstone(s) of deleted markers from %s", kept, tomb_path)

    inbox: asyncio.Queue[tuple[str, str, bytes | None]] = asyncio.Queue()
    rx: asyncio.Queue[tuple[str, bytes]] = asyncio.Queue(maxsize=RX_BACKLOG)
    links = [_Link(u, tls, rx, on_up=lambda url: emit(state.on_link_up(url, time.time()))) for u in urls]
    by_url = {lk.url: lk for lk in links}
    exit_code = EXIT_TERMINATED

    def stop_with(code: int) -> None:
        nonlocal exit_code
        if not stop.is_set():  # the first signal says how the bridge ended
            exit_code = code
        stop.set()

    for sig, code in ((signal.SIGTERM, EXIT_TERMINATED), (signal.SIGINT, EXIT_INTERRUPTED)):
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):  # not the main thread
            loop.add_signal_handler(sig, stop_with, code)
    mission = settings.mission
    fetching: set[asyncio.Task[None]] = set()  # route queries in flight (a reference keeps each alive)

    def enqueue(kind: str) -> Any:
        import zenoh

        def callback(sample: zenoh.Sample) -> None:
            payload = None if sample.kind == zenoh.SampleKind.DELETE else sample.payload.to_bytes()
            loop.call_soon_threadsafe(inbox.put_nowait, (kind, str(sample.key_expr), payload))

        return callback

    subs = [
        session.declare_subscriber(keys.threats(mission), enqueue("threat")),
        session.declare_subscriber(keys.zones(mission), enqueue("zone")),
        session.declare_subscriber(keys.teams(mission), enqueue("team")),
        session.declare_subscriber(keys.unit_states_any(mission), enqueue("state")),
        session.declare_subscriber(keys.unit_directions(mission), enqueue("direction")),
        session.declare_subscriber(keys.events(mission), enqueue("event")),
    ]

    # markers are acknowledged writes (wire.delivery): put while no planner runs, in force once one starts
    writes = Deliverer(session, mission, lambda line: log.warning("tak: %s", line))

    def publish(action: ZenohPut | ZenohDelete) -> None:
        if isinstance(action, ZenohPut):
            writes.put(action.key, action.payload)
        else:
            writes.delete(action.key)

    def emit(out: Outputs) -> None:
        for data in out.cot:
            for link in links:
                link.send(data)
        for url, data in out.to_link:  # a device heard on a read-only link is reached by the others
            for link in links if by_url[url].read_only else (by_url[url],):
                link.send(data)
        for action in out.zenoh:
            publish(action)
        for unit in out.routes:
            task = asyncio.create_task(fetch_route(unit))
            fetching.add(task)
            task.add_done_callback(fetching.discard)

    async def fetch_route(unit: str) -> None:
        def ask() -> Any:
            for reply in session.get(keys.preview(mission, unit), timeout=PREVIEW_TIMEOUT_S):
                if reply.ok is not None:
                    return decode_plan_result(reply.ok.payload.to_bytes())
            return None

        try:
            result = await loop.run_in_executor(None, ask)
        except InputError as exc:
            log.warning("tak: route of %s: bad preview reply: %s", unit, exc)
            return
        if result is not None:
            emit(state.on_route(unit, result.path, result.status.value, result.length, time.time()))

    async def from_zenoh() -> None:
        while True:
            kind, key, payload = await inbox.get()
            now = time.time()
            if kind == "threat":
                emit(state.on_threat(key, payload, now))
            elif kind == "zone":
                emit(state.on_zone(key, payload, now))
            elif kind == "team":
                state.on_team(key, payload)  # its members' remarks, at their next direction
            elif payload is None:
                continue
            elif kind == "state":
                state.on_state(key, payload)
            elif kind == "direction":
                emit(state.on_direction(key, payload, now))
            elif kind == "event":
                emit(state.on_event(payload, now))

    async def zones_in_force() -> None:
        """The zones a planner already holds, once at start: a bridge started late still shows them."""

        def ask() -> list[m.ZoneSummary]:
            for reply in session.get(keys.worlds(mission), timeout=PREVIEW_TIMEOUT_S):
                if reply.ok is not None:
                    with contextlib.suppress(InputError):
                        return list(m.decode_world_snapshot(reply.ok.payload.to_bytes()).zones)
            return []

        emit(state.on_zones_in_force(await loop.run_in_executor(None, ask), time.time()))

    async def from_tak() -> None:
        while True:
            source, data = await rx.get()
            emit(state.on_cot(data, time.time(), source))

    async def ticker() -> None:
        while True:
            emit(state.tick(time.time()))
            if keeper is not None:
                keeper.keep(state)
            await asyncio.sleep(TICK_S)

    tasks = [
        asyncio.create_task(c)
        for c in (from_zenoh(), from_tak(), ticker(), zones_in_force(), *(lk.run() for lk in links))
    ]
    try:
        if ready is not None:
            await asyncio.gather(*(lk.connected.wait() for lk in links))
            ready.set()
        await stop.wait()
    finally:
        pending = [*tasks, *fetching]
        for t in pending:
            t.cancel()
        await asyncio.gather(*pending, return_exceptions=True)
        writes.close()
        for sub in subs:
            sub.undeclare()
        if keeper is not None:
            keeper.keep(state)
        log.info("tak: stopped: links closed, subscribers undeclared")
    return exit_code  # the signal handlers stay until the loop closes: a second signal changes nothing


def _encoding() -> Any:
    from pfp_service.wire.encoding import zenoh_encoding

    return zenoh_encoding()


def run(
    settings: BridgeSettings,
    urls: Sequence[str],
    zenoh_conf: Any,
    tls: TlsFiles | None = None,
    stop: asyncio.Event | None = None,
    ready: asyncio.Event | None = None,
    tombstones: Path | None = None,
) -> int:
    """Run the bridge until ``stop`` is set, SIGTERM (returns 0) or SIGINT (returns 130).

    Args:
        settings: mission, origin, threat defaults and rates.
        urls: pytak ``COT_URL``s, one per TAK link.
        zenoh_conf: the client's ``zenoh.Config``.
        tls: certificate files for ``tls://`` links.
        stop: set it (from the loop's thread) to end the bridge.
        ready: set once every link has connected the first time.
        tombstones: the file deleted markers' tombstones are kept in across restarts (None: memory only).

    Returns:
        the exit code: 0 stopped or terminated, 130 interrupted.

    Raises:
        ZenohError: the session could not be opened.
    """
    import zenoh

    from pfp_service.errors import map_zenoh_errors

    with map_zenoh_errors("--connect"):
        session = zenoh.open(zenoh_conf)
    with session:
        from pfp_clients.frames import check_origin

        note = check_origin(session, settings.mission, settings.origin)  # InputError: another origin
        if note is not None:
            log.info("tak: %s", note)
        code = asyncio.run(_main(settings, urls, tls, session, stop or asyncio.Event(), ready, tombstones))
        _hold_signals()
    return code


def _hold_signals() -> None:
    """Ignore SIGTERM and SIGINT while the session closes: the closed loop put the defaults back, and
    a second signal would kill the process half-way through closing, which can hang Zenoh at exit."""
    import threading

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, signal.SIG_IGN)
