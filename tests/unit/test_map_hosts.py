"""``pfp map`` answers only requests for a host it serves: the DNS-rebinding defence, with forged Host headers."""

from __future__ import annotations

import base64
import http.client
import json
import os
import subprocess
import sys
import uuid
from urllib.parse import urlparse

import pytest
import zenoh

from tests.browser.test_map_browser import map_process
from tests.conftest import ROOT
from tests.zenoh_util import free_port


@pytest.fixture(scope="module")
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


def _request(url: str, path: str, host: str | None, headers: dict[str, str] | None = None):
    """A raw request with exactly this ``Host`` header (None: no Host header at all)."""
    u = urlparse(url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=10)
    try:
        conn.putrequest("GET", path, skip_host=True, skip_accept_encoding=True)
        if host is not None:
            conn.putheader("Host", host)
        for k, v in (headers or {}).items():
            conn.putheader(k, v)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()


WS_UPGRADE = {
    "Upgrade": "websocket",
    "Connection": "Upgrade",
    "Sec-WebSocket-Key": base64.b64encode(os.urandom(16)).decode(),
    "Sec-WebSocket-Version": "13",
}


def _ws_status(url: str, host: str) -> int:
    u = urlparse(url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=10)
    try:
        conn.putrequest("GET", "/ws", skip_host=True, skip_accept_encoding=True)
        conn.putheader("Host", host)
        for k, v in WS_UPGRADE.items():
            conn.putheader(k, v)
        conn.endheaders()
        return conn.getresponse().status
    finally:
        conn.close()


@pytest.mark.proc
def test_forged_hosts_get_421_and_nothing_else(router):
    mission = "hosts" + uuid.uuid4().hex[:8]
    with map_process(router, mission, "--allow-edit", "--allowed-host", "Map.Example.") as url:
        port = urlparse(url).port
        for host in (f"127.0.0.1:{port}", f"localhost:{port}", "localhost", f"map.example:{port}"):
            status, body = _request(url, "/api/state", host)
            assert status == 200 and json.loads(body)["config"]["mission"] == mission, host
        assert _request(url, "/", f"[::1]:{port}")[0] == 200
        for host in (
            f"evil.example:{port}",
            "evil.example",
            f"127.0.0.1.evil.example:{port}",
            "10.0.0.7",
            "",
        ):
            for path in ("/", "/api/state", "/api/stats", "/static/map.js", "/api/preview/u1"):
                status, body = _request(url, path, host)
                assert (status, body) == (421, b""), (host, path, status, body[:80])
        status, body = _request(url, "/api/state", None)  # no Host header at all: aiohttp's own 400
        assert status in (400, 421) and mission.encode() not in body, (status, body)
        assert _ws_status(url, f"evil.example:{port}") == 421
        assert _ws_status(url, f"127.0.0.1:{port}") == 101
        # an edit from a rebinding page is refused before the edit header is even looked at
        u = urlparse(url)
        conn = http.client.HTTPConnection(u.hostname, u.port, timeout=10)
        conn.putrequest("PUT", "/api/goal/u1", skip_host=True)
        body = b'{"position": [1, 2]}'
        for k, v in (("Host", "evil.example"), ("X-PFP-Edit", "1"), ("Content-Length", str(len(body)))):
            conn.putheader(k, v)
        conn.endheaders(body)
        r = conn.getresponse()
        assert (r.status, r.read()) == (421, b"")
        conn.close()
        stats = json.loads(_request(url, "/api/stats", f"127.0.0.1:{port}")[1])
        assert stats["refused_hosts"] == 27  # 5 hosts x 5 paths, the WebSocket and the edit


@pytest.mark.proc
@pytest.mark.parametrize("bad", ["evil example", "a/b", "http://x", "-x", ""])
def test_a_bad_allowed_host_is_one_line_exit_2(bad):
    r = subprocess.run(
        [sys.executable, "-m", "pfp_service", "map", "--allowed-host", bad, "--connect", "tcp/127.0.0.1:1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "--allowed-host" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.unit
@pytest.mark.parametrize(
    ("header", "bind", "extra", "ok"),
    [
        ("127.0.0.1:8080", "127.0.0.1", (), True),
        ("LOCALHOST:8080", "127.0.0.1", (), True),
        ("[::1]:8080", "::1", (), True),
        ("localhost.", "127.0.0.1", (), True),
        ("evil.example:8080", "127.0.0.1", (), False),
        ("192.168.1.5:8080", "127.0.0.1", (), False),
        ("192.168.1.5:8080", "192.168.1.5", (), True),
        ("localhost:8080", "192.168.1.5", (), False),
        ("map.local:8080", "192.168.1.5", ("map.local",), True),
        ("10.1.2.3:8080", "0.0.0.0", (), True),
        ("[fe80::1]:8080", "::", (), True),
        ("evil.example", "0.0.0.0", (), False),
        ("localhost", "0.0.0.0", (), True),
        (None, "127.0.0.1", (), False),
        ("", "127.0.0.1", (), False),
        ("[::1", "::1", (), False),
    ],
)
def test_host_allowed(header, bind, extra, ok):
    from pfp_clients.map.server import host_allowed

    assert host_allowed(header, bind, extra) is ok


def _ws_origin_status(url: str, origin: str | None) -> tuple[int, bytes]:
    """An upgrade to ``/ws`` with the right ``Host`` and this ``Origin``; the status and the first bytes."""
    u = urlparse(url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=10)
    try:
        conn.putrequest("GET", "/ws", skip_host=True, skip_accept_encoding=True)
        conn.putheader("Host", f"127.0.0.1:{u.port}")
        if origin is not None:
            conn.putheader("Origin", origin.format(port=u.port))
        for k, v in WS_UPGRADE.items():
            conn.putheader(k, v)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, (r.read() if r.status != 101 else b"")
    finally:
        conn.close()


@pytest.mark.proc
def test_a_websocket_from_another_origin_gets_403_and_no_picture(router):
    mission = "origin" + uuid.uuid4().hex[:8]
    with map_process(router, mission) as url:
        for origin in ("http://evil.example", "http://127.0.0.1:1", "null", "https://evil.example:{port}"):
            status, body = _ws_origin_status(url, origin)
            assert status == 403 and mission.encode() not in body, (origin, status, body[:80])
        assert _ws_origin_status(url, "http://127.0.0.1:{port}")[0] == 101  # the map's own page
        assert _ws_origin_status(url, None)[0] == 101  # no browser: as /api/state
        port = urlparse(url).port
        stats = json.loads(_request(url, "/api/stats", f"127.0.0.1:{port}")[1])
        assert stats["refused_origins"] == 4


@pytest.mark.unit
@pytest.mark.parametrize(
    ("origin", "host", "ok"),
    [
        (None, "127.0.0.1:8080", True),
        ("http://127.0.0.1:8080", "127.0.0.1:8080", True),
        ("http://LOCALHOST:8080", "localhost:8080", True),
        ("https://map.example.", "map.example", True),
        ("http://[::1]:8080", "[::1]:8080", True),
        ("http://evil.example", "127.0.0.1:8080", False),
        ("http://127.0.0.1:9090", "127.0.0.1:8080", False),
        ("null", "127.0.0.1:8080", False),
        ("file://", "127.0.0.1:8080", False),
        ("http://127.0.0.1:8080", None, False),
    ],
)
def test_origin_allowed(origin, host, ok):
    from pfp_clients.map.server import origin_allowed

    assert origin_allowed(origin, host) is ok
