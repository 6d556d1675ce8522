"""``pfp tak`` against taky, a real third-party TAK server, with stand-in ATAK devices on TCP.

Each test starts taky (``python -m taky.cot``, in-memory persistence: it keeps
markers until their stale time and replays them to every new connection), a
planner and the bridge as subprocesses.  A ``Device`` is what ATAK does on
the wire: it connects, announces itself (its SA, ``a-f-G-U-C`` with
``<takv>``, ``<contact>`` and ``<__group>``) and reads everything the server
sends.  A ``Proxy`` between the bridge and taky cuts the bridge's link on demand.
"""

from __future__ import annotations

import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import pytest

pytest.importorskip("pytak")
pytest.importorskip("taky")

from pfp_clients.tak import cot

from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from tests.unit.test_tak_cot import delete
from tests.zenoh_util import ROOT, Inbox, client, free_port, planner_process, put_json

pytestmark = pytest.mark.multi

ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=87.5)
MISSION = "taky"


def marker(uid: str, t: float, ttl: float, remarks: bytes = b"", lat: float = 58.4150) -> bytes:
    """A hostile ground marker as ATAK sends it (an XML declaration, then the event)."""
    return (
        (
            f'<?xml version="1.0" encoding="UTF-8"?><event version="2.0" uid="{uid}" type="a-h-G-U-C" '
            f'how="h-g-i-g-o" time="{cot.iso(t)}" start="{cot.iso(t)}" stale="{cot.iso(t + ttl)}">'
            f'<point lat="{lat}" lon="15.6300" hae="0" ce="9999999" le="9999999"/><detail>'
            f'<contact callsign="{uid}"/>'
        ).encode()
        + remarks
        + b"</detail></event>"
    )


def huge_marker(uid: str, t: float, ttl: float, size: int = 10_000_000) -> bytes:
    """A hostile marker of ``size`` bytes: remarks in 1 MB pieces (libxml2, in taky, caps one text node at 10 MB)."""
    piece = b"<remarks>" + b"A" * 999_000 + b"</remarks>"
    return marker(uid, t, ttl, piece * (size // len(piece) + 1))


class Device:
    """A stand-in ATAK device on the TAK server: its SA on connect, then every event it is sent, parsed."""

    def __init__(self, port: int, uid: str) -> None:
        self.uid = uid
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.sock.settimeout(None)
        self.events: queue.Queue[tuple[float, ET.Element]] = queue.Queue()
        self.seen: list[tuple[float, ET.Element]] = []  # what wait() has taken from events
        threading.Thread(target=self._read, daemon=True).start()
        self.send(self.sa(time.time()))

    def sa(self, t: float) -> bytes:
        return (
            f'<?xml version="1.0" encoding="UTF-8"?><event version="2.0" uid="{self.uid}" type="a-f-G-U-C" '
            f'how="m-g" time="{cot.iso(t)}" start="{cot.iso(t)}" stale="{cot.iso(t + 120)}">'
            f'<point lat="58.41" lon="15.62" hae="90" ce="9" le="9"/><detail><takv platform="ATAK-CIV" '
            f'version="4.10" device="stand-in" os="34"/><contact callsign="{self.uid}" endpoint="*:-1:stcp"/>'
            f'<__group name="Cyan" role="Team Member"/></detail></event>'
        ).encode()

    def _read(self) -> None:
        buf = b""
        while True:
            try:
                chunk = self.sock.recv(1 << 20)
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while b"</event>" in buf:
                one, buf = buf.split(b"</event>", 1)
                start = one.find(b"<event")
                if start >= 0:
                    with suppress(ET.ParseError):
                        self.events.put((time.monotonic(), ET.fromstring(one[start:] + b"</event>")))

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def wait(self, where: Callable[[ET.Element], bool], timeout: float = 20.0) -> tuple[float, ET.Element]:
        """The first event ever received that matches (waiting up to ``timeout`` for one): (when, event)."""
        for t, ev in self.seen:
            if where(ev):
                return t, ev
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                t, ev = self.events.get(timeout=left)
            except queue.Empty:
                break
            self.seen.append((t, ev))
            if where(ev):
                return t, ev
        raise TimeoutError(f"{self.uid}: no matching event in {timeout} s")

    def close(self) -> None:
        with suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()


class Proxy:
    """A TCP relay to ``port``; ``cut()`` drops every connection through it (the bridge then reconnects)."""

    def __init__(self, port: int) -> None:
        self.upstream = port
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.conns: list[socket.socket] = []
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                down, _ = self.server.accept()
            except OSError:
                return
            up = socket.create_connection(("127.0.0.1", self.upstream))
            self.conns += [down, up]
            for a, b in ((down, up), (up, down)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    @staticmethod
    def _pump(a: socket.socket, b: socket.socket) -> None:
        while True:
            try:
                data = a.recv(1 << 16)
                if not data:
                    break
                b.sendall(data)
            except OSError:
                break
        for s in (a, b):
            with suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)

    def cut(self) -> None:
        conns, self.conns = self.conns, []
        for s in conns:
            with suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()

    def close(self) -> None:
        self.cut()
        self.server.close()


@contextmanager
def taky_server(folder: Path) -> Iterator[int]:
    """taky on a free loopback port (plain TCP, in-memory persistence); yields the port."""
    port = free_port()
    folder.mkdir(parents=True, exist_ok=True)
    conf = folder / "taky.conf"
    conf.write_text(
        f"[taky]\nhostname = taky.test\nnode_id = TAKY\nbind_ip = 127.0.0.1\nroot_dir = {folder}\n\n"
        f"[cot_server]\nport = {port}\n\n[ssl]\nenabled = false\n"
    )
    log = open(folder / "taky.log", "w+")  # noqa: SIM115 - closed below, after the process
    proc = subprocess.Popen(
        [sys.executable, "-m", "taky.cot", "-c", str(conf), "-l", "info"],
        cwd=folder,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if proc.poll() is not None or time.monotonic() > deadline:
                    log.seek(0)
                    raise AssertionError(f"taky did not start: {log.read()[-2000:]}") from None
                time.sleep(0.1)
        yield port
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


class Bridge:
    """``pfp tak`` as a subprocess: its stderr lines in a queue, all of them kept in ``seen``."""

    def __init__(self, endpoint: str, port: int, state_dir: Path, *extra: str) -> None:
        args = [sys.executable, "-m", "pfp_service", "tak", "--connect", endpoint, "--mission", MISSION]
        args += ["--origin", f"{ORIGIN.lat},{ORIGIN.lon},{ORIGIN.alt}", "--rate-s", "0.2"]
        args += ["--refresh-s", "600", "--cot-url", f"tcp://127.0.0.1:{port}", "--state-dir", str(state_dir)]
        self.proc = subprocess.Popen(
            [*args, *extra],
            cwd=ROOT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.seen.append(line.rstrip("\n"))
            self.lines.put(line.rstrip("\n"))

    def wait_line(self, fragment: str, timeout: float = 30.0) -> float:
        """Wait for a line with ``fragment``; returns when it came (monotonic)."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            if fragment in line:
                return time.monotonic()
        raise TimeoutError(f"no line with {fragment!r}; saw {self.seen[-15:]}")

    def count(self, fragment: str) -> int:
        return sum(fragment in line for line in self.seen)

    def stop(self, sig: int = signal.SIGTERM) -> tuple[int, float]:
        """Send ``sig``; returns the exit code and how long the bridge took to exit."""
        t0 = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            code = self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait()
        return code, time.monotonic() - t0


@contextmanager
def running(endpoint: str, port: int, state_dir: Path, *extra: str) -> Iterator[Bridge]:
    b = Bridge(endpoint, port, state_dir, *extra)
    try:
        yield b
    finally:
        b.stop()


@contextmanager
def device(port: int, uid: str) -> Iterator[Device]:
    d = Device(port, uid)
    try:
        yield d
    finally:
        d.close()


@pytest.fixture(scope="module")
def planner():
    origin = f"{ORIGIN.lat},{ORIGIN.lon},{ORIGIN.alt}"
    with planner_process("--state-dir", "none", "--origin", origin, mission=MISSION) as (endpoint, _proc):
        yield endpoint


def _threats_held(session, want: int | None = None, timeout: float = 10.0) -> int:
    """Wait until the planner holds ``want`` threats (None: any number); returns how many it holds."""
    deadline = time.monotonic() + timeout
    got = None
    while time.monotonic() < deadline:
        for r in session.get(keys.planner_statuses(MISSION), timeout=1.0):
            if r.ok is not None:
                got = m.decode_planner_status(r.ok.payload.to_bytes()).threats
                if want is None or got == want:
                    return got
        time.sleep(0.1)
    raise AssertionError(f"planner holds {got} threats, expected {want}")


def _no_put(inbox: Inbox, seconds: float) -> None:
    with suppress(TimeoutError):
        got = inbox.get(timeout=seconds, where=lambda msg: msg is not None)
        raise AssertionError(f"a threat came back: {got}")


@pytest.mark.alone
def test_a_10_mb_marker_the_server_keeps_costs_the_bridge_that_one_event(planner, tmp_path):
    def fresh_threat(bridge: Bridge, i: int) -> float:
        """A fresh marker from the device; returns how long until it is a threat on Zenoh."""
        t0 = time.monotonic()
        dev.send(marker(f"fresh-{i}", time.time(), ttl=300))
        fresh[i].get(timeout=10, where=lambda msg: msg is not None)
        return time.monotonic() - t0

    with (
        taky_server(tmp_path / "taky") as port,
        client(planner) as s,
        device(port, "ANDROID-stand-in-1") as dev,
        running(planner, port, tmp_path / "state") as bridge,
    ):
        bridge.wait_line("connected tcp://")
        fresh = [Inbox(s, keys.threat(MISSION, cot.threat_id(f"fresh-{i}"))) for i in range(3)]
        # the hostile marker and a fresh one right behind it: taky sends the 10 MB first, 4 KiB a turn
        sent = time.monotonic()
        dev.send(huge_marker("hostile-10mb", time.time(), ttl=60) + marker("fresh-0", time.time(), ttl=300))
        skipped = bridge.wait_line("skipped a CoT event of", timeout=60)
        fresh[0].get(timeout=10, where=lambda msg: msg is not None)
        behind_s, after_skip_s = time.monotonic() - sent, time.monotonic() - skipped
        assert after_skip_s < 1.0, after_skip_s
        alone_s = fresh_threat(bridge, 1)
        assert alone_s < 1.0, alone_s

        # a bridge that connects now is sent the kept 10 MB marker first, by the server
        with running(planner, port, tmp_path / "state2") as second:
            started = second.wait_line("connected tcp://")
            replayed = second.wait_line("skipped a CoT event of", timeout=60)
            second_s = fresh_threat(second, 2)
            assert second_s < 1.0, second_s
            assert second.count("connected tcp://") == 1 and second.count("failed") == 0, second.seen
        assert bridge.count("connected tcp://") == 1 and bridge.count("failed") == 0, bridge.seen
        for i in range(3):
            s.delete(keys.threat(MISSION, cot.threat_id(f"fresh-{i}")))
        print(
            f"\n10 MB hostile marker: through taky and skipped in {skipped - sent:.2f} s; a fresh marker "
            f"sent right behind it a threat {behind_s:.2f} s after sending ({after_skip_s * 1e3:.0f} ms after "
            f"the skip); one sent after: {alone_s * 1e3:.0f} ms; a new bridge: replay skipped "
            f"{replayed - started:.2f} s after connecting, then a fresh marker in {second_s * 1e3:.0f} ms; "
            f"reconnects 0 and 0"
        )


def test_a_deleted_marker_stays_deleted_across_a_reconnect_and_a_restart(planner, tmp_path):
    with (
        taky_server(tmp_path / "taky") as port,
        client(planner) as s,
        device(port, "ANDROID-stand-in-2") as dev,
    ):
        proxy = Proxy(port)
        tid = cot.threat_id("ghost")
        inbox = Inbox(s, keys.threat(MISSION, tid))
        before = _threats_held(s)
        try:
            with running(planner, proxy.port, tmp_path / "state") as bridge:
                bridge.wait_line("connected tcp://")
                now = time.time()
                dev.send(marker("ghost", now - 500, ttl=600))  # sent 500 s ago: 100 s left
                put = inbox.get(timeout=10, where=lambda msg: msg is not None)
                assert put["ttl_s"] == pytest.approx(100.0, abs=3.0)  # stale - now, not stale - time
                dev.send(delete("ghost", t=time.time()))
                assert inbox.get(timeout=10, where=lambda msg: msg is None) is None
                _threats_held(s, before)
                proxy.cut()  # the link drops; the bridge reconnects and taky replays the marker
                bridge.wait_line("failed")
                bridge.wait_line("connected tcp://")
                _no_put(inbox, 3.0)
                assert bridge.count("connected tcp://") == 2
            with running(planner, proxy.port, tmp_path / "state") as restarted:
                restarted.wait_line("tombstone(s) of deleted markers")
                restarted.wait_line("connected tcp://")
                _no_put(inbox, 3.0)
                _threats_held(s, before)
                # the server does keep it, and replays it: a device that joins now is sent it
                with device(port, "ANDROID-late") as late:
                    late.wait(lambda e: e.get("uid") == "ghost", timeout=10)
                # the same uid placed again after the delete is a new marker
                dev.send(marker("ghost", time.time(), ttl=300))
                assert inbox.get(timeout=10, where=lambda msg: msg is not None)["ttl_s"] > 290
                s.delete(keys.threat(MISSION, tid))
        finally:
            proxy.close()


def test_a_late_device_gets_every_route_at_once_at_the_origin_altitude(planner, tmp_path):
    with (
        taky_server(tmp_path / "taky") as port,
        client(planner) as s,
        device(port, "ANDROID-early") as early,
        running(planner, port, tmp_path / "state") as bridge,
    ):
        bridge.wait_line("connected tcp://")
        route_uid = f"pfp.route.{MISSION}.u7"
        deadline = time.monotonic() + 30
        seq = 0
        while True:  # until the bridge's subscribers are up and the planner has a route
            seq += 1
            put_json(
                s, keys.unit_state(MISSION, "u7"), {"position": [0.0, 0.0], "kind": "manned", "seq": seq}
            )
            put_json(s, keys.unit_goal(MISSION, "u7"), {"position": [400.0, 300.0]})
            with suppress(TimeoutError):
                early.wait(lambda e: e.get("uid") == route_uid, timeout=1.0)
                break
            assert time.monotonic() < deadline, bridge.seen[-10:]
        put_json(
            s,
            keys.threat(MISSION, "ambush"),
            {"position": [200.0, 100.0], "sigma_range": 30, "sigma_lateral": 20},
        )
        early.wait(lambda e: e.get("uid") == f"pfp.threat.{MISSION}.ambush", timeout=10)
        time.sleep(1.0)  # past the bridge's announce interval: what follows is for the late device alone
        joined = time.monotonic()
        with device(port, "ANDROID-late-joiner") as late:
            arrived, route = late.wait(lambda e: e.get("uid") == route_uid, timeout=10)
            delay = arrived - joined
            assert delay < 5.0, delay
            _, unit = late.wait(lambda e: e.get("uid") == f"pfp.unit.{MISSION}.u7", timeout=10)
            _, threat = late.wait(lambda e: e.get("uid") == f"pfp.threat.{MISSION}.ambush", timeout=10)
        assert unit.get("type") == "a-f-G-U-C" and threat.get("type") == "a-h-G"
        p = threat.find("point")  # taky re-writes a point it relays with 6 decimals (about 0.1 m)
        assert ORIGIN.to_local(float(p.get("lat")), float(p.get("lon"))) == pytest.approx(
            (200.0, 100.0), abs=0.2
        )
        for ev in (unit, threat):
            assert float(ev.find("point").get("hae")) == ORIGIN.alt
        points = [lk.get("point").split(",") for lk in route.findall("detail/link")]
        assert len(points) >= 2 and all(float(p[2]) == ORIGIN.alt for p in points)
        print(f"\nroute on a late device {delay:.2f} s after it connected")
        s.delete(keys.unit_goal(MISSION, "u7"))
        s.delete(keys.threat(MISSION, "ambush"))


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 0), (signal.SIGINT, 130)])
def test_pfp_tak_stops_cleanly_on_sigterm_and_sigint(planner, tmp_path, sig, code):
    with taky_server(tmp_path / "taky") as port:
        bridge = Bridge(planner, port, tmp_path / "state")
        try:
            bridge.wait_line("connected tcp://")
            got, took = bridge.stop(sig)
        finally:
            bridge.stop(signal.SIGKILL)
        time.sleep(0.2)  # the reader thread takes the last lines
        assert got == code and took < 10.0, (got, took, bridge.seen)
        assert not any("Traceback" in line for line in bridge.seen), bridge.seen
        assert bridge.count("subscribers undeclared") == 1 and bridge.seen[-1] == "pfp tak: stopped"
        print(f"\npfp tak on {signal.Signals(sig).name}: exit {got} in {took:.2f} s")
