"""The map's lat/lon frame in Chromium over offline tiles, against the planner's geodesy (split from ``test_map_browser``)."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from pfp_service.wire import keys
from tests.browser.test_map_browser import map_process, mission, page_at, playwright  # noqa: F401 - fixtures
from tests.zenoh_util import client, planner_process, put_json

pytestmark = [pytest.mark.browser, pytest.mark.alone]


# -- the lat/lon frame over offline tiles ---------------------------------------------------------
@contextmanager
def tile_server() -> Iterator[tuple[str, list[str]]]:
    """An offline tile server on loopback: any path answers one PNG; yields (URL template, paths asked)."""
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    from pfp_clients.map.server import STATIC_DIR

    png = (STATIC_DIR / "vendor" / "leaflet" / "images" / "layers.png").read_bytes()
    asked: list[str] = []

    class Tiles(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            asked.append(self.path)
            self.send_response(200)
            self.send_header("Content-Type", "image/png")
            self.send_header("Content-Length", str(len(png)))
            self.end_headers()
            self.wfile.write(png)

        def log_message(self, *args: Any) -> None:
            pass

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), Tiles)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}/{{z}}/{{x}}/{{y}}.png", asked
    finally:
        httpd.shutdown()
        httpd.server_close()


def test_lat_lon_frame_matches_the_planners_geodesy_over_offline_tiles(playwright, mission):  # noqa: F811 - fixtures
    from pfp_service.geo import parse_origin

    origin = parse_origin("48.1173,11.5167,520")
    with (
        planner_process(mission=mission) as (endpoint, _planner),
        client(endpoint) as s,
        tile_server() as (tiles, asked),
        map_process(endpoint, mission, "--origin", "48.1173,11.5167,520", "--tiles", tiles) as url,
        page_at(playwright, url) as page,
    ):
        put_json(s, keys.unit_state(mission, "g1"), {"position": [1500.0, -800.0], "kind": "manned"})
        page.wait("() => pfpMap.units.has('g1') && pfpMap.units.get('g1').marker !== null")
        lat, lon = page.js(
            "() => { const ll = pfpMap.units.get('g1').marker.getLatLng(); return [ll.lat, ll.lng]; }"
        )
        want = origin.to_geodetic(1500.0, -800.0)
        assert (lat, lon) == pytest.approx(want, abs=1e-9)  # about 0.1 mm
        for x, y in ((0.0, 0.0), (-20_000.0, 35_000.0), (42_000.0, -9_000.0)):
            back = page.js("(p) => toMetres(toLatLng(p))", [x, y])
            assert back == pytest.approx([x, y], abs=1e-4)
            assert page.js(
                "(p) => { const ll = toLatLng(p); return [ll.lat, ll.lng]; }", [x, y]
            ) == pytest.approx(origin.to_geodetic(x, y), abs=1e-9)
        assert page.js("() => pfpMap.map.options.crs === L.CRS.EPSG3857")
        # the tiles under the view come from the offline server, in Web Mercator z/x/y
        page.wait("() => document.querySelectorAll('.leaflet-tile-loaded').length > 0")
        lat0, lon0 = math.radians(origin.lat), origin.lon

        def near_origin(path: str) -> bool:
            z, x, y = (int(v) for v in path.removesuffix(".png").strip("/").split("/"))
            ox, oy = (lon0 + 180) / 360 * 2**z, (1 - math.asinh(math.tan(lat0)) / math.pi) / 2 * 2**z
            return abs(x - ox) <= 3 and abs(y - oy) <= 3

        assert any(near_origin(path) for path in asked), asked
        assert page.errors == []
