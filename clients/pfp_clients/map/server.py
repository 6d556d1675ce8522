"""The map's web side: one page, a WebSocket of deltas and a small API, over the Zenoh ``feed``.

One asyncio task, the pump, wakes ``push_hz`` times a second,
applies everything queued in one batch, and offers the delta to every
browser.  Flow control is per browser: a page acknowledges each frame once it
has drawn it, and until then the deltas meant for it are merged into one
(``model.merge_deltas``).  So a page gets at most ``push_hz`` frames a second
and never more than it can draw, and no backlog grows anywhere: the inbox is
drained whole every tick, and what waits for a slow page is one merged delta,
never a queue of them.  A page that has just connected gets the snapshot in
the tick it joins, after that tick's delta, so it never sees a change twice.

Blocking Zenoh calls (status and world queries, previews, puts: ``Feed``)
run on the default executor, never on the event loop.  The page
talks to the planner only through this server, and this server only through
the keys every other client uses: edits are the same puts as ``pfp inject``.

HTTP API (JSON):
    GET    /                      the page
    GET    /ws                    WebSocket: a snapshot, then deltas
    GET    /api/state             the snapshot, for scripts and tests
    GET    /api/stats             samples in, inbox backlog, tick cost, frames sent
    GET    /api/preview/{unit}    the planner's preview of the unit, with its ETA
    PUT    /api/threat/{id}       a ThreatUpdate      (--allow-edit only)
    DELETE /api/threat/{id}
    PUT    /api/goal/{unit}       a Goal              (--allow-edit only)
    DELETE /api/goal/{unit}
    PUT    /api/zone/{id}         a ZoneUpdate        (--allow-edit only): a keep-out zone
    DELETE /api/zone/{id}
    GET    /api/geojson           threats and keep-out zones as RFC 7946 GeoJSON (needs --origin)
    GET    /api/terrain, /api/viewshed/{threat}   with --terrain: terrain_api.py
Edits need the header ``X-PFP-Edit: 1``: a custom header cannot be sent
cross-origin without a CORS preflight, which this server never grants, so
another web page open in the operator's browser cannot edit the mission.

Every request, the WebSocket included, must name a host this server serves
in its ``Host`` header (``host_allowed``), or it gets 421 and an empty body:
a DNS-rebinding page (evil.example resolved to 127.0.0.1) reaches the port
but names its own host, so it can neither read the mission nor edit it.

A WebSocket is not bound by the same-origin policy: any page the operator has
open may connect to ``ws://127.0.0.1:PORT/ws`` with the right ``Host`` and read
the live picture.  So ``/ws`` also checks ``Origin`` (``origin_allowed``): a
browser always sends it, and it must be this server's own origin (the ``Host``
the request names); another origin gets 403 before the upgrade.  A client that
is no browser sends no ``Origin`` and is let in, as ``/api/state`` lets it in.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
from aiohttp import WSMsgType, web

from pfp_clients.ground import Ground
from pfp_clients.map.feed import Feed, PreviewError
from pfp_clients.map.hosts import host_allowed, origin_allowed
from pfp_clients.map.model import MapModel, eta_s, merge_deltas
from pfp_clients.map.terrain_api import TerrainApi
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import decode_goal, decode_threat, keys
from pfp_service.wire.messages import decode_zone

__all__ = ["STATIC_DIR", "MapOptions", "MapServer", "host_allowed", "origin_allowed", "serve"]

log = logging.getLogger("pfp.map")
STATIC_DIR = Path(__file__).resolve().parent / "static"
_EDIT_HEADER = "X-PFP-Edit"
_SEND_TIMEOUT_S = 2.0  # a browser that takes longer to accept one frame is dropped


@dataclass(frozen=True)
class MapOptions:
    """How the map runs.

    Attributes:
        mission: the mission's key chunk.
        host, port: where the page is served (port 0: any free port).
        allow_edit: accept threat and goal edits from the page.
        push_hz: deltas per second to each browser, at most.
        stale_s: a unit silent this long is drawn stale (the planner's ``unit_stale_s``).
        status_period_s: how often the planners' status is asked.
        query_timeout_s: how long a status, world or preview query waits.
        origin: the mission origin (the planner's (0, 0)); None draws plain metres.
        tiles: a tile URL template for an offline tile server (lat/lon only).
        allowed_hosts: names a browser may use for this server besides ``host`` (``--allowed-host``).
        terrain: the DEM (``--terrain``; needs ``origin``), and the target height its viewsheds are for.
    """

    mission: str = keys.DEFAULT_MISSION
    host: str = "127.0.0.1"
    port: int = 8080
    allow_edit: bool = False
    push_hz: float = 5.0
    stale_s: float = 10.0
    status_period_s: float = 1.0
    query_timeout_s: float = 2.0
    origin: Origin | None = None
    tiles: str | None = None
    allowed_hosts: tuple[str, ...] = ()
    terrain: Ground | None = None
    target_height_m: float = 1.8


class _Browser:
    """One connected page: its socket, whether it is drawing a frame, and what waits for it."""

    def __init__(self, ws: web.WebSocketResponse) -> None:
        self.ws = ws
        self.dropped = False
        self.in_flight = False  # sent a frame the page has not acknowledged yet
        self.pending: dict[str, Any] | None = None


class MapServer:
    """The map's feed, its model and its web app, on one open session.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        opts: see ``MapOptions``.
        clock: wall-clock Unix seconds (the page shows ages and TTLs from it).
    """

    def __init__(self, session: Any, opts: MapOptions, clock: Callable[[], float] = time.time) -> None:
        self.opts = opts
        self.clock = clock
        self.feed = Feed(session, opts.mission, opts.query_timeout_s, opts.origin)
        self.model = MapModel(stale_s=opts.stale_s)
        self._browsers: list[_Browser] = []
        self._joining: list[_Browser] = []
        self.frames_sent = 0
        self.ticks = 0
        self.tick_ms_max = 0.0
        self.tick_ms_total = 0.0
        self.refused_hosts = 0
        self.refused_origins = 0
        self.terrain = None
        if opts.terrain is not None and opts.origin is not None:
            self.terrain = TerrainApi(
                opts.terrain, opts.origin, opts.target_height_m, lambda: self.model.threats
            )

    # -- the pump --------------------------------------------------------------------
    def config_view(self) -> dict[str, Any]:
        """What the page needs to draw: the mission, editing, and the frame (metres or lat/lon)."""
        o = self.opts
        return {
            "mission": o.mission,
            "allow_edit": o.allow_edit,
            # the page projects with the same ENU plane as pfp_service.geo (map.js, enuToGeodetic)
            "origin": None if o.origin is None else msgspec.to_builtins(o.origin),
            "tiles": o.tiles,
            "stale_s": o.stale_s,
            "push_hz": o.push_hz,
            "terrain": None if self.terrain is None else {"path": Path(self.terrain.ground.path).name},
        }

    def stats(self) -> dict[str, Any]:
        """How the server keeps up: samples taken, what waits in the inbox, tick cost, frames sent."""
        return {
            "cpu_s": time.process_time(),  # this process's CPU seconds, threads included
            "samples_in": self.feed.samples_in,
            "backlog": self.feed.backlog(),
            "ticks": self.ticks,
            "tick_ms_mean": self.tick_ms_total / self.ticks if self.ticks else None,
            "tick_ms_max": self.tick_ms_max,
            "frames_sent": self.frames_sent,
            "refused_hosts": self.refused_hosts,
            "refused_origins": self.refused_origins,
            "browsers": len(self._browsers),
            "units": len(self.model.units),
            "threats": len(self.model.threats),
        }

    def snapshot(self) -> dict[str, Any]:
        return {**self.model.snapshot(self.clock()), "config": self.config_view()}

    async def _send(self, browser: _Browser, text: str) -> None:
        browser.in_flight = True
        try:
            await asyncio.wait_for(browser.ws.send_str(text), _SEND_TIMEOUT_S)
            self.frames_sent += 1
        except (TimeoutError, ConnectionError, RuntimeError):
            browser.dropped = True
            with contextlib.suppress(Exception):
                await browser.ws.close()

    async def tick(self) -> None:
        """One pump step: apply what came, send each idle page its delta, then snapshots to newcomers."""
        now = self.clock()
        self.model.apply(self.feed.drain(), now)
        delta = self.model.take_delta(now)
        sends = []
        shared: dict[str, str] = {}  # pages in step get the same text, encoded once
        for b in self._browsers:
            if delta is not None:
                b.pending = (
                    delta if b.pending is None else merge_deltas(b.pending, delta, self.model.track_max)
                )
            if b.pending is not None and not b.in_flight:
                key = "delta" if b.pending is delta else str(id(b))
                text = shared.get(key) or msgspec.json.encode(b.pending).decode()
                shared[key] = text
                b.pending = None
                sends.append(self._send(b, text))
        if self._joining:
            text = msgspec.json.encode(self.snapshot()).decode()
            sends += [self._send(b, text) for b in self._joining]
            self._browsers += self._joining
            self._joining = []
        if sends:
            await asyncio.gather(*sends)
        self._browsers = [b for b in self._browsers if not (b.dropped or b.ws.closed)]

    async def pump(self) -> None:
        period = 1.0 / self.opts.push_hz
        while True:
            started = time.monotonic()
            try:
                await self.tick()
            except Exception:  # the page must outlive any one bad tick
                log.exception("map: tick failed")
            spent_ms = (time.monotonic() - started) * 1e3
            self.ticks += 1
            self.tick_ms_total += spent_ms
            self.tick_ms_max = max(self.tick_ms_max, spent_ms)
            await asyncio.sleep(max(0.0, period - (time.monotonic() - started)))

    async def poll_status(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            try:
                await loop.run_in_executor(None, self.feed.ask_status)
            except Exception as exc:  # a router restart: keep asking
                log.warning("map: status query failed: %s", exc)
            await asyncio.sleep(self.opts.status_period_s)

    # -- HTTP --------------------------------------------------------------------------
    @web.middleware
    async def _host_guard(
        self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
    ) -> web.StreamResponse:
        header = request.headers.get("Host")
        if host_allowed(header, self.opts.host, self.opts.allowed_hosts):
            return await handler(request)
        self.refused_hosts += 1
        if self.refused_hosts <= 10:  # a rebinding page may knock often: the first few say enough
            log.warning("map: refused a request for host %r (not one this map serves)", (header or "")[:80])
        return web.Response(status=421, body=b"")

    def app(self) -> web.Application:
        app = web.Application(client_max_size=64 * 1024, middlewares=[self._host_guard])
        app.router.add_get("/", self._index)
        app.router.add_get("/ws", self._ws)
        app.router.add_get("/api/state", self._state)
        app.router.add_get("/api/stats", self._stats)
        app.router.add_get("/api/preview/{unit}", self._preview)
        app.router.add_put("/api/threat/{id}", self._put_threat)
        app.router.add_delete("/api/threat/{id}", self._delete_threat)
        app.router.add_put("/api/goal/{unit}", self._put_goal)
        app.router.add_delete("/api/goal/{unit}", self._delete_goal)
        app.router.add_put("/api/zone/{id}", self._put_zone)
        app.router.add_delete("/api/zone/{id}", self._delete_zone)
        app.router.add_get("/api/geojson", self._geojson)
        if self.terrain is not None:
            self.terrain.add(app)
        app.router.add_static("/static/", STATIC_DIR)
        return app

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    async def _state(self, request: web.Request) -> web.Response:
        return web.json_response(self.snapshot(), dumps=lambda o: msgspec.json.encode(o).decode())

    async def _stats(self, request: web.Request) -> web.Response:
        return web.json_response(self.stats())

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if not origin_allowed(origin, request.headers.get("Host")):
            self.refused_origins += 1
            if self.refused_origins <= 10:
                log.warning(
                    "map: refused a WebSocket from origin %r (not this map's page)",
                    origin[:80] if origin else "",
                )
            return web.Response(status=403, text="cross-origin WebSocket refused")
        ws = web.WebSocketResponse(heartbeat=20.0)
        await ws.prepare(request)
        browser = _Browser(ws)
        self._joining.append(browser)
        async for msg in ws:  # the page says only "ack": it has drawn the last frame
            if msg.type == WSMsgType.TEXT and msg.data == "ack":
                browser.in_flight = False
            elif msg.type == WSMsgType.ERROR:
                break
        browser.dropped = True
        return ws

    async def _preview(self, request: web.Request) -> web.Response:
        unit = request.match_info["unit"]
        try:
            keys.check_chunk(unit, "unit")
        except InputError as exc:
            return web.json_response({"error": exc.reason, "field": "unit"}, status=400)
        loop = asyncio.get_running_loop()
        try:
            answer = await loop.run_in_executor(None, self.feed.ask_preview, unit)
        except InputError as exc:
            return web.json_response({"unit": unit, "error": str(exc)}, status=502)
        # A planner that refuses (no goal, busy) or does not answer is still a 200 whose body
        # has ``error``: news for the operator, not a fault of the page (and browsers log every
        # non-2xx response as a console error).
        if isinstance(answer, PreviewError):
            return web.json_response({"unit": unit, "error": answer.error, "field": answer.field})
        body = msgspec.to_builtins(answer)
        speed = self.model.speed_of(unit)
        body["eta_s"], body["speed_mps"] = eta_s(answer.length, speed), speed
        return web.json_response({"unit": unit, "preview": body})

    def _edit_refused(self, request: web.Request) -> web.Response | None:
        if not self.opts.allow_edit:
            return web.json_response(
                {"error": "editing is off (start pfp map with --allow-edit)"}, status=403
            )
        if request.headers.get(_EDIT_HEADER) != "1":
            return web.json_response({"error": f"missing header {_EDIT_HEADER}: 1"}, status=403)
        return None

    async def _edit(
        self, request: web.Request, key_of: Callable[[str], str], decode: Any | None
    ) -> web.Response:
        refused = self._edit_refused(request)
        if refused is not None:
            return refused
        name = next(iter(request.match_info.values()))
        try:
            key = key_of(name)
            msg = decode(await request.read()) if decode is not None else None
        except InputError as exc:
            return web.json_response({"error": exc.reason, "field": exc.path}, status=400)
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, self.feed.send, key, msg)
        log.info("map: %s %s", "put" if msg is not None else "delete", key)
        return web.json_response({"ok": True, "key": key})

    async def _put_threat(self, request: web.Request) -> web.Response:
        return await self._edit(request, lambda t: keys.threat(self.opts.mission, t), decode_threat)

    async def _delete_threat(self, request: web.Request) -> web.Response:
        return await self._edit(request, lambda t: keys.threat(self.opts.mission, t), None)

    async def _put_zone(self, request: web.Request) -> web.Response:
        def decode(body: bytes) -> Any:  # metres, or {lat, lon} with an origin
            return decode_zone(body, None, self.opts.origin)

        return await self._edit(request, lambda z: keys.zone(self.opts.mission, z), decode)

    async def _delete_zone(self, request: web.Request) -> web.Response:
        return await self._edit(request, lambda z: keys.zone(self.opts.mission, z), None)

    async def _geojson(self, request: web.Request) -> web.Response:
        """The threats and keep-out zones the map shows, as one RFC 7946 FeatureCollection."""
        from pfp_service.geojson import feature_collection
        from pfp_service.world import translate

        origin = self.opts.origin
        if origin is None:
            return web.json_response(
                {"error": "GeoJSON is in lon/lat: start pfp map with --origin"}, status=409
            )
        model = self.model
        threats = [translate.threat(t.update, tid) for tid, t in model.threats.items()]
        zones = [translate.zone(z, zid) for zid, z in model.zone_updates.items()]
        fc = feature_collection(origin, threats, zones=zones, name=f"pfp map {self.opts.mission}")
        return web.json_response(fc, content_type="application/geo+json")

    async def _put_goal(self, request: web.Request) -> web.Response:
        return await self._edit(request, lambda u: keys.unit_goal(self.opts.mission, u), decode_goal)

    async def _delete_goal(self, request: web.Request) -> web.Response:
        return await self._edit(request, lambda u: keys.unit_goal(self.opts.mission, u), None)


async def serve(
    session: Any,
    opts: MapOptions,
    stop: asyncio.Event | None = None,
    say: Callable[[str], None] = print,
    ready: Callable[[str], None] | None = None,
) -> int:
    """Serve the map on an open session until ``stop`` is set (or SIGTERM/SIGINT); returns 0.

    Args:
        ready: called with the page's URL once it is served (``embed`` waits on it).

    Raises:
        InputError: ``--http``, when the address cannot be bound.
    """
    stop = stop or asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):  # not the main thread
            loop.add_signal_handler(sig, stop.set)
    server = MapServer(session, opts)
    server.feed.declare()
    runner = web.AppRunner(server.app(), handle_signals=False, access_log=None)
    await runner.setup()
    tasks: list[asyncio.Task[None]] = []
    try:
        site = web.TCPSite(runner, opts.host, opts.port)
        try:
            await site.start()
        except OSError as exc:
            raise InputError(
                "--http", f"cannot listen on {opts.host}:{opts.port}: {exc.strerror or exc}"
            ) from None
        host, port = runner.addresses[0][:2]
        shown = f"[{host}]" if ":" in host else host
        answered = await loop.run_in_executor(None, server.feed.ask_world)
        notes = ["editing on" if opts.allow_edit else "read-only"]
        if answered:
            notes.append(f"world from {answered} planner{'s' if answered > 1 else ''}")
        url = f"http://{shown}:{port}/"
        say(f"pfp map: mission {opts.mission} at {url} ({', '.join(notes)})")
        if ready is not None:
            ready(url)
        tasks = [asyncio.create_task(server.pump()), asyncio.create_task(server.poll_status())]
        await stop.wait()
    finally:
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        await runner.cleanup()
        server.feed.undeclare()
        if server.terrain is not None:
            server.terrain.close()
    return 0
