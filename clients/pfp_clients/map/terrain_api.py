"""The map server's terrain routes (``pfp map --terrain DEM``): the hillshade, and a threat's viewshed.

HTTP API (JSON; images as PNG data URLs with their lat/lon corners, ``terrain.Overlay.view``):
    GET /api/terrain            the DEM's hillshade
    GET /api/viewshed/{threat}  where the threat sees a target ``--target-height`` tall, out to its reach

Both are computed on one worker thread of their own, never on the event loop
nor on the executor the Zenoh queries use, so a viewshed never delays a
frame, a preview or an edit.  A viewshed asked for again while it is being
computed waits for the same computation; one that takes longer than
``WAIT_S`` is answered "still computing" and kept when done, so the next
click shows it.  A threat off the DEM, or standing on no-data, is an answer
with ``error`` (a 200: news for the operator, as a preview's refusal is).
"""

from __future__ import annotations

import asyncio
import functools
import logging
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from aiohttp import web

from pfp_clients.ground import Ground
from pfp_clients.map.terrain import Overlay, Viewsheds, hillshade_overlay, threat_reach_m
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import ThreatUpdate
from pfp_service.world import translate

__all__ = ["WAIT_S", "TerrainApi"]

log = logging.getLogger("pfp.map")
WAIT_S = 10.0  # a request waits this long for its viewshed; the computation itself ends by its bounds


class TerrainApi:
    """The terrain routes over ``ground``, drawn on ``origin``'s plane; ``threats()`` the model's threats."""

    def __init__(self, ground: Ground, origin: Origin, target_height_m: float, threats: Any) -> None:
        self.ground = ground
        self.origin = origin
        self.threats = threats
        self.viewsheds = Viewsheds(ground, target_height_m)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pfp-map-terrain")
        self._hillshade: asyncio.Future[Overlay] | None = None
        self._pending: dict[tuple[float, ...], asyncio.Future[Overlay]] = {}

    def add(self, app: web.Application) -> None:
        app.router.add_get("/api/terrain", self._get_hillshade)
        app.router.add_get("/api/viewshed/{threat}", self._get_viewshed)

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    async def _get_hillshade(self, request: web.Request) -> web.Response:
        if self._hillshade is None:
            loop = asyncio.get_running_loop()
            self._hillshade = loop.run_in_executor(self._pool, hillshade_overlay, self.ground, self.origin)
        try:
            shade = await asyncio.shield(self._hillshade)
        except InputError as exc:  # the DEM placed on this origin's plane breaks a bound
            return web.json_response({"error": exc.reason})
        return web.json_response(shade.view())

    async def _get_viewshed(self, request: web.Request) -> web.Response:
        tid = request.match_info["threat"]
        held = self.threats().get(tid)
        if held is None:
            return web.json_response({"threat": tid, "error": f"no threat {tid!r} on the map"}, status=404)
        update: ThreatUpdate = held.update
        lat, lon = self.origin.to_geodetic(*update.position)
        eye = float(translate.threat(update, tid).observer_height_m)
        key = self.viewsheds.key(lat, lon, eye, threat_reach_m(update, tid))
        got = self.viewsheds.get(key)
        if got is None:
            fut = self._pending.get(key)
            if fut is None:
                fut = asyncio.get_running_loop().run_in_executor(self._pool, self.viewsheds.compute, key)
                self._pending[key] = fut
                fut.add_done_callback(functools.partial(self._done, key))
            try:
                got = await asyncio.wait_for(asyncio.shield(fut), WAIT_S)
            except TimeoutError:
                return web.json_response({"threat": tid, "error": "its viewshed is still being computed"})
            except InputError as exc:
                return web.json_response({"threat": tid, "error": exc.reason})
        return web.json_response({"threat": tid, **got.view()})

    def _done(self, key: tuple[float, ...], fut: asyncio.Future[Overlay]) -> None:
        self._pending.pop(key, None)
        if fut.cancelled():
            return
        exc = fut.exception()
        if exc is None:
            self.viewsheds.keep(key, fut.result())
        elif not isinstance(exc, InputError):
            log.warning("map: a viewshed failed: %s", exc)
