"""A page on another origin, open in the operator's Chromium, cannot read the map's live picture over
``/ws``; the map's own page still can (issue 35)."""

from __future__ import annotations

import http.server
import json
import shutil
import tempfile
import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import zenoh

from tests.browser.test_map_browser import CHROMIUM_ARGS, map_process, playwright  # noqa: F401 (a fixture)
from tests.zenoh_util import free_port

pytestmark = [pytest.mark.browser, pytest.mark.alone]

# Opens the WebSocket and says what came: "open", the size of each message, and the close code.
_PROBE = """(url) => new Promise((resolve) => {
    const got = [];
    const ws = new WebSocket(url);
    ws.onopen = () => got.push("open");
    ws.onmessage = (m) => { got.push("message " + m.data.length); ws.close(); };
    ws.onerror = () => got.push("error");
    ws.onclose = (e) => resolve({got, code: e.code});
    setTimeout(() => resolve({got, code: "timeout"}), 8000);
})"""


@contextmanager
def _other_site() -> Iterator[str]:
    """An HTTP server on another loopback port serving one harmless-looking page; yields its URL."""

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = b"<!doctype html><p>an unrelated page</p>"
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: Any) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


@pytest.fixture
def router():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    try:
        yield endpoint
    finally:
        session.close()


def test_a_page_on_another_origin_gets_no_websocket_and_the_maps_own_page_does(playwright: Any, router):  # noqa: F811
    from tests.browser.test_map_browser import CHROMIUM

    mission = "origin" + uuid.uuid4().hex[:8]
    profile = tempfile.mkdtemp(prefix="pfp-map-origin-")
    with map_process(router, mission) as url:
        ws_url = url.replace("http://", "ws://").rstrip("/") + "/ws"
        context = playwright.chromium.launch_persistent_context(
            profile, executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS
        )
        try:
            page = context.new_page()
            # another site on this machine (another port: another origin), as a page the operator
            # has open beside the map; a public one would meet Chromium's private-network block first
            with _other_site() as other:
                page.goto(other)
                assert page.evaluate("() => location.origin") == other.rstrip("/")
                foreign = page.evaluate(_PROBE, ws_url)
            page.goto(url)  # the map's own page, as the operator opens it
            own = page.evaluate(_PROBE, ws_url)
        finally:
            context.close()
            shutil.rmtree(profile, ignore_errors=True)
    print(f"from another origin: {foreign}; from the map's page: {own}")
    assert "open" not in foreign["got"] and not any(g.startswith("message") for g in foreign["got"]), foreign
    assert foreign["code"] == 1006, foreign  # the handshake failed: the server said 403
    assert own["got"][:2] == ["open", own["got"][1]] and own["got"][1].startswith("message"), own
