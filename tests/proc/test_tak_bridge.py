"""``pfp tak`` against a real planner on loopback Zenoh and loopback TCP/UDP TAK listeners."""

from __future__ import annotations

import os
import queue
import socket
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress

import pytest

pytest.importorskip("pytak")

from pfp_clients.tak import cot

from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from pfp_service.world.translate import decode_plan_result
from tests.zenoh_util import ROOT, Inbox, client, free_port, planner_process, put_json

pytestmark = pytest.mark.proc

ORIGIN = Origin(lat=58.4105, lon=15.6213)
MISSION = "tak"


def _lines(stream, q: queue.Queue[str]) -> None:
    for line in stream:
        q.put(line.rstrip("\n"))


@contextmanager
def bridge(endpoint: str, *urls: str) -> Iterator[queue.Queue[str]]:
    """``pfp tak`` as a subprocess (``urls``: COT URLs, then any further flags); yields its stderr lines."""
    args = [sys.executable, "-m", "pfp_service", "tak", "--connect", endpoint, "--mission", MISSION]
    args += ["--origin", f"{ORIGIN.lat},{ORIGIN.lon}", "--rate-s", "0.2", "--refresh-s", "600"]
    for u in urls:
        args += ["--cot-url", u] if "://" in u else [u]
    proc = subprocess.Popen(
        args, cwd=ROOT, env={**os.environ, "PYTHONUNBUFFERED": "1"}, stderr=subprocess.PIPE, text=True
    )
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=_lines, args=(proc.stderr, lines), daemon=True).start()
    try:
        yield lines
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def wait_line(lines: queue.Queue[str], fragment: str, timeout: float = 20.0) -> str:
    deadline = time.monotonic() + timeout
    seen = []
    while (left := deadline - time.monotonic()) > 0:
        try:
            line = lines.get(timeout=left)
        except queue.Empty:
            break
        seen.append(line)
        if fragment in line:
            return line
    raise TimeoutError(f"no line with {fragment!r}; saw {seen[-10:]}")


def wait_lines(lines: queue.Queue[str], *fragments: str, timeout: float = 20.0) -> None:
    """Wait until every fragment has been in a line, in any order."""
    left_to_see = set(fragments)
    deadline = time.monotonic() + timeout
    while left_to_see:
        line = wait_line(lines, "", timeout=max(0.0, deadline - time.monotonic()))
        left_to_see = {f for f in left_to_see if f not in line}


def wait_cot(q: queue.Queue[bytes], where: Callable[[ET.Element], bool], timeout: float = 20.0) -> ET.Element:
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        try:
            ev = ET.fromstring(q.get(timeout=left))
        except queue.Empty:
            break
        if where(ev):
            return ev
    raise TimeoutError("no matching CoT event")


class TcpTakServer:
    """A TAK server stand-in: accepts the bridge, splits what it sends into events, can send back."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.events: queue.Queue[bytes] = queue.Queue()
        self.conn: socket.socket | None = None
        self.accepted = threading.Event()
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        self.conn, _ = self.sock.accept()
        self.accepted.set()
        buf = b""
        while True:
            try:
                chunk = self.conn.recv(65536)
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while b"</event>" in buf:
                one, buf = buf.split(b"</event>", 1)
                self.events.put(one.strip() + b"</event>")

    def send(self, data: bytes) -> None:
        assert self.conn is not None
        self.conn.sendall(data)

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.sock.close()


def _status_threats(session, want: int, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    got = None
    while time.monotonic() < deadline:
        for r in session.get(keys.planner_statuses(MISSION), timeout=1.0):
            if r.ok is not None:
                got = m.decode_planner_status(r.ok.payload.to_bytes()).threats
                if got == want:
                    return
        time.sleep(0.1)
    raise AssertionError(f"planner holds {got} threats, expected {want}")


@pytest.fixture(scope="module")
def planner():
    with planner_process(mission=MISSION) as (endpoint, _proc):
        yield endpoint


def test_tcp_marker_in_threat_out_route_out(planner):
    from tests.unit.test_tak_cot import delete, hostile

    server = TcpTakServer()
    try:
        with bridge(planner, f"tcp://127.0.0.1:{server.port}") as lines, client(planner) as s:
            assert server.accepted.wait(20), "the bridge never connected"
            tid = cot.threat_id("ANDROID-7f.h1")
            inbox = Inbox(s, keys.threat(MISSION, tid))
            # a bad event first: logged and dropped, and the next one still gets through
            server.send(b"<event uid='x' type='a-h-G'><point lat='1'/></event>")
            now = time.time()
            server.send(hostile(t=now, ttl=300))
            put = inbox.get(timeout=10, where=lambda msg: msg is not None)
            assert put["position"] == pytest.approx(list(ORIGIN.to_local(58.415, 15.63)), abs=1e-6)
            assert put["facing_deg"] == 225.0 and put["ttl_s"] == pytest.approx(300.0, abs=0.01)
            _status_threats(s, 1)
            assert "dropped a CoT event" in wait_line(lines, "dropped")
            server.send(delete("ANDROID-7f.h1", t=time.time()))
            assert inbox.get(timeout=10, where=lambda msg: msg is None) is None
            _status_threats(s, 0)

            # a threat from elsewhere goes to TAK as a hostile marker with a stable uid
            put_json(
                s,
                keys.threat(MISSION, "ambush"),
                {"position": [300.0, -250.0], "sigma_range": 40, "sigma_lateral": 25},
            )
            ev = wait_cot(server.events, lambda e: e.get("uid") == f"pfp.threat.{MISSION}.ambush")
            assert ev.get("type") == "a-h-G"
            p = ev.find("point")
            assert ORIGIN.to_local(float(p.get("lat")), float(p.get("lon"))) == pytest.approx(
                (300.0, -250.0), abs=1e-6
            )

            # a unit with a goal: its marker (unmanned) with course, and its route in order
            put_json(
                s, keys.unit_state(MISSION, "u1"), {"position": [0.0, 0.0], "kind": "unmanned", "seq": 1}
            )
            put_json(s, keys.unit_goal(MISSION, "u1"), {"position": [600.0, 500.0]})
            time.sleep(0.3)
            put_json(
                s, keys.unit_state(MISSION, "u1"), {"position": [0.0, 0.0], "kind": "unmanned", "seq": 2}
            )
            unit = wait_cot(server.events, lambda e: e.get("uid") == f"pfp.unit.{MISSION}.u1")
            assert unit.get("type") == "a-f-G-E-V"
            assert unit.find("detail/remarks").text.startswith("pfp ")
            route = wait_cot(server.events, lambda e: e.get("type") == "b-m-r")
            assert route.find("detail/remarks").text.startswith("pfp route for u1: reached")
            links = route.findall("detail/link")
            assert (
                len(links) >= 3 and links[0].get("type") == "b-m-p-w" and links[-1].get("type") == "b-m-p-w"
            )
            xy = [ORIGIN.to_local(*map(float, lk.get("point").split(",")[:2])) for lk in links]
            assert xy[0] == pytest.approx((0.0, 0.0), abs=1e-3)
            gone = [((600.0 - x) ** 2 + (500.0 - y) ** 2) ** 0.5 for x, y in xy]
            assert gone[-1] < 50.0 and gone == sorted(gone, reverse=True), (
                gone
            )  # waypoints in order to the goal
            # the same path as the live preview, thinned
            (reply,) = [r for r in s.get(keys.preview(MISSION, "u1"), timeout=5.0) if r.ok is not None]
            path = decode_plan_result(reply.ok.payload.to_bytes()).path
            assert xy[-1] == pytest.approx(path[-1], abs=1e-3)
            s.delete(keys.threat(MISSION, "ambush"))
            rm = wait_cot(server.events, lambda e: e.get("type") == "t-x-d-d")
            assert rm.find("detail/link").get("uid") == f"pfp.threat.{MISSION}.ambush"
            s.delete(keys.unit_goal(MISSION, "u1"))
    finally:
        server.close()


def test_udp_both_ways(planner):
    from tests.unit.test_tak_cot import hostile

    out_port, in_port = free_port(), free_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", out_port))
    rx.settimeout(0.5)
    got: queue.Queue[bytes] = queue.Queue()
    stop = threading.Event()

    def listen() -> None:
        while not stop.is_set():
            try:
                got.put(rx.recv(65536))
            except TimeoutError:
                continue
            except OSError:
                return

    threading.Thread(target=listen, daemon=True).start()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        urls = (f"udp+wo://127.0.0.1:{out_port}", f"udp+ro://127.0.0.1:{in_port}")
        with bridge(planner, *urls) as lines, client(planner) as s:
            wait_lines(lines, "connected udp+wo", "connected udp+ro")  # the links connect in any order
            deadline = time.monotonic() + 15
            ev = None
            while ev is None and time.monotonic() < deadline:  # until the bridge's subscriber has propagated
                put_json(
                    s,
                    keys.threat(MISSION, "udp1"),
                    {"position": [10.0, 20.0], "sigma_range": 5, "sigma_lateral": 5},
                )
                with suppress(TimeoutError):
                    ev = wait_cot(got, lambda e: e.get("uid") == f"pfp.threat.{MISSION}.udp1", timeout=1.0)
            assert ev is not None and ev.get("type") == "a-h-G"
            tid = cot.threat_id("udp-marker")
            inbox = Inbox(s, keys.threat(MISSION, tid))
            tx.sendto(b"garbage", ("127.0.0.1", in_port))
            put, deadline = None, time.monotonic() + 15
            while put is None and time.monotonic() < deadline:  # until the inbox's subscriber has propagated:
                # a put before it reaches the router is not delivered to it (the same marker again is the same put)
                tx.sendto(hostile(uid="udp-marker", t=time.time()), ("127.0.0.1", in_port))
                with suppress(TimeoutError):
                    put = inbox.get(timeout=1.0, where=lambda msg: msg is not None)
            assert put is not None, "the marker sent over UDP never reached Zenoh"
            assert put["sigma_range"] == 50.0  # the bridge's default shape
            assert "dropped" in wait_line(lines, "dropped")
            s.delete(keys.threat(MISSION, "udp1"))
            s.delete(keys.threat(MISSION, tid))
    finally:
        stop.set()
        rx.close()
        tx.close()


class TlsTakServer(TcpTakServer):
    """The TCP stand-in behind mutual TLS: it asks for the bridge's certificate and checks it against the CA."""

    def __init__(self, certs) -> None:
        import ssl

        ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH, cafile=str(certs / "ca.pem"))
        ctx.load_cert_chain(str(certs / "takserver.pem"), str(certs / "takserver-key.pem"))
        ctx.verify_mode = ssl.CERT_REQUIRED
        self.ctx = ctx
        self.peer_cn = ""
        super().__init__()

    def _serve(self) -> None:
        raw, _ = self.sock.accept()
        self.conn = self.ctx.wrap_socket(raw, server_side=True)
        subject = dict(x[0] for x in self.conn.getpeercert()["subject"])
        self.peer_cn = subject.get("commonName", "")
        self.accepted.set()
        buf = b""
        while True:
            try:
                chunk = self.conn.recv(65536)
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while b"</event>" in buf:
                one, buf = buf.split(b"</event>", 1)
                self.events.put(one.strip() + b"</event>")


def test_tls_to_a_tak_server_with_client_certificates(planner, tmp_path):
    pytest.importorskip("cryptography")
    from tests.unit.test_tak_cot import hostile

    certs = tmp_path / "certs"
    subprocess.run(
        [sys.executable, str(ROOT / "docker" / "gen-certs.py"), "--out", str(certs), "takserver", "bridge"],
        check=True,
        capture_output=True,
    )
    server = TlsTakServer(certs)
    try:
        url = f"tls://127.0.0.1:{server.port}"
        tls = ["--tls-cert", str(certs / "bridge.pem"), "--tls-key", str(certs / "bridge-key.pem")]
        tls += ["--tls-ca", str(certs / "ca.pem")]
        with bridge(planner, url, *tls) as _lines, client(planner) as s:
            assert server.accepted.wait(20), "the bridge never completed the TLS handshake"
            assert server.peer_cn == "bridge"
            tid = cot.threat_id("tls-marker")
            inbox = Inbox(s, keys.threat(MISSION, tid))
            server.send(hostile(uid="tls-marker", t=time.time()))
            assert inbox.get(timeout=10, where=lambda msg: msg is not None)["sigma_lateral"] == 30.0
            put_json(
                s,
                keys.threat(MISSION, "tls1"),
                {"position": [5.0, 5.0], "sigma_range": 5, "sigma_lateral": 5},
            )
            ev = wait_cot(server.events, lambda e: e.get("uid") == f"pfp.threat.{MISSION}.tls1")
            assert ev.get("type") == "a-h-G"
            s.delete(keys.threat(MISSION, "tls1"))
            s.delete(keys.threat(MISSION, tid))
    finally:
        server.close()
