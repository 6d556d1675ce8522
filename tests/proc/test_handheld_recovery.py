"""A handheld that recovers: the link lost and found, the planner restarted (split from ``test_handheld``)."""

from __future__ import annotations

import asyncio
import time
import uuid
from pathlib import Path

import pytest
from pfp_clients.handheld_link import open_link
from pfp_clients.handheld_model import (
    HandheldModel,
    Settings,
)
from pfp_clients.nmea import LocalFrame
from pfp_clients.nmea_feed import NmeaReader, open_nmea

from pfp_service.wire import keys
from tests.unit.test_handheld import _app, _direction, _next_msg, _text, _until, _xor, planner  # noqa: F401 - a fixture
from tests.zenoh_util import Inbox, client, free_port

SIZE = (50, 20)


# -- issue 16: a handheld that recovers ----------------------------------------------------
@pytest.mark.unit
def test_eta_uses_the_speed_it_shows():
    m = HandheldModel(Settings(unit="u1", speed_mps=1.4, speed_up=10.0), (0.0, 0.0), now=0.0)
    m.on_direction(_direction(distance=140.0), now=0.0)
    assert m.eta_speed_mps() == pytest.approx(14.0)
    assert m.view(0.0).eta_s == pytest.approx(10.0)  # 140 m at the 14 m/s the walk really goes
    gps = HandheldModel(Settings(unit="u1", speed_mps=1.4, walk=False, gps=True), None, now=0.0)
    gps.on_direction(_direction(distance=30.0), now=0.0)
    assert gps.view(0.0).eta_s == pytest.approx(30.0 / 1.4)  # standing: the walking speed
    gps.on_fix(0.0, 0.0, 0.0)
    gps.on_fix(3.0, 0.0, 1.0)  # 3 m/s over the ground
    assert gps.view(1.0).eta_s == pytest.approx(10.0)


def _serve(endpoint: str, mission: str):
    import subprocess
    import sys

    from tests.conftest import ROOT

    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--listen", endpoint, "--mission", mission],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip


def _stop(proc) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except Exception:
        proc.kill()
        proc.wait()


@pytest.mark.proc
def test_starts_with_the_router_down_and_resends_its_goal_to_a_restarted_planner(tmp_path: Path):
    from pfp_clients.handheld_link import RetryingLink

    from pfp_service.node.config import client_zenoh_config

    mission, uid = "r" + uuid.uuid4().hex[:10], "late"
    endpoint = f"tcp/127.0.0.1:{free_port()}"

    async def scenario():
        link = RetryingLink(lambda: client_zenoh_config([endpoint]), endpoint, mission, uid, retry_s=0.3)
        procs = []
        try:
            settings = Settings(unit=uid, walk=False, goal=(20.0, 0.0), stale_after_s=2.0)
            app = _app(link, mission, settings)
            app.model.on_link(False, f"connecting to {endpoint}")
            async with app.run_test(size=SIZE) as pilot:
                await _until(pilot, lambda: "no router answers" in _text(app, "note"), "the no-router note")
                assert "STALE" in _text(app, "age") or "NO UPDATE" in _text(app, "age")
                assert app.last_view.stale and not link.connected
                procs.append(_serve(endpoint, mission))  # the router comes up
                await _until(pilot, lambda: app.last_view.status_label == "EN ROUTE", "guidance", timeout=30)
                assert _text(app, "note") == "" and not app.last_view.stale
                _stop(procs.pop())  # the planner restarts: it forgets every goal
                await _until(pilot, lambda: app.last_view.stale, "stale while it is down", timeout=15)
                procs.append(_serve(endpoint, mission))
                # nobody cancelled the goal, so the handheld gives it to the new planner
                await _until(
                    pilot, lambda: app.last_view.status_label == "EN ROUTE", "guidance again", timeout=40
                )
                assert app.last_view.bearing == "090° E"
        finally:
            link.close()
            for p in procs:
                _stop(p)

    asyncio.run(scenario())


@pytest.mark.proc
def test_g_sets_the_goal_from_a_prompt(planner):  # noqa: F811 - the fixture imported above
    endpoint, mission, _ = planner
    uid = "prompt"

    async def scenario():
        with client(endpoint) as s:
            goals = Inbox(s, keys.unit_goal(mission, uid))
            with open_link([endpoint], mission, uid) as link:
                app = _app(link, mission, Settings(unit=uid, walk=False))
                async with app.run_test(size=SIZE) as pilot:
                    await _until(pilot, lambda: app.last_view.status_label == "NO GOAL", "no goal yet")
                    await pilot.press("g")
                    await pilot.press(*"nonsense", "enter")
                    await _until(
                        pilot,
                        lambda: "expected X,Y" in str(app.screen.query_one("#why").content),
                        "the reason",
                    )
                    field = app.screen.query_one("#goal")
                    field.value = ""
                    await pilot.press(*"0,20", "enter")
                    goal = await _next_msg(pilot, goals, lambda m: True, "the goal on the wire")
                    assert goal["position"] == [0.0, 20.0]
                    await _until(pilot, lambda: app.last_view.bearing == "000° N", "a bearing north")
                    assert "goal set to (0, 20)" in app.model.note

    asyncio.run(scenario())


def _gga(utc: str, frame: LocalFrame, x: float, y: float) -> str:
    lat, lon = frame.to_geodetic(x, y)
    lat_min, lon_min = (abs(lat) - int(abs(lat))) * 60, (abs(lon) - int(abs(lon))) * 60
    body = f"GPGGA,{utc},{int(lat):02d}{lat_min:08.5f},N,{int(lon):03d}{lon_min:08.5f},E,1,09,0.8,500.0,M,47.0,M,,"
    return f"${body}*{_xor(body):02X}\r\n"


def _arrivals(reader: NmeaReader, inbox, want: int, timeout: float = 10.0) -> list[float]:
    from pfp_clients.handheld_link import FixIn

    times = []
    deadline = time.monotonic() + timeout
    while len(times) < want and time.monotonic() < deadline:
        try:
            item = inbox.get(timeout=0.1)
        except Exception:
            continue
        if isinstance(item, FixIn):
            times.append(time.monotonic())
    return times


@pytest.mark.unit
def test_an_nmea_file_is_paced_by_its_own_timestamps_or_by_nmea_rate(tmp_path: Path):
    import queue

    frame = LocalFrame(48.0, 11.0)
    log = tmp_path / "walk.nmea"
    # fixes 0.3 s apart (the file's own UTC times): a second apart, as a receiver sends them, is 3 s of waiting
    log.write_text("".join(_gga(f"101010.{30 * i:02d}", frame, 10.0 + i, 50.0) for i in range(4)))
    inbox: queue.Queue = queue.Queue()
    reader = NmeaReader(open_nmea(str(log)), frame, inbox)
    assert reader.paced  # a regular file: a recording to replay
    reader.start()
    times = _arrivals(reader, inbox, 4)
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert len(gaps) == 3 and all(0.25 < g < 0.9 for g in gaps), gaps  # 0.3 s apart, as recorded
    inbox2: queue.Queue = queue.Queue()
    fast = NmeaReader(open_nmea(str(log)), frame, inbox2, rate_hz=20.0)
    fast.start()
    times = _arrivals(fast, inbox2, 4)
    assert len(times) == 4 and times[-1] - times[0] < 0.6


@pytest.mark.unit
def test_a_binary_nmea_file_is_bad_sentences_that_end(tmp_path: Path):
    import queue
    import random

    from pfp_clients.handheld_link import NmeaEnded, NmeaRejected

    blob = tmp_path / "firmware.bin"
    rng = random.Random(7)
    blob.write_bytes(bytes(rng.getrandbits(8) for _ in range(2_000_000)))
    inbox: queue.Queue = queue.Queue(maxsize=100_000)
    reader = NmeaReader(open_nmea(str(blob)), LocalFrame(48.0, 11.0), inbox)
    t0, cpu0 = time.monotonic(), time.process_time()
    reader.start()
    reader.join(timeout=20)
    assert not reader.is_alive(), "the reader is still going"
    items = list(inbox.queue)
    assert isinstance(items[-1], NmeaEnded) and "not NMEA" in items[-1].reason
    assert sum(isinstance(i, NmeaRejected) for i in items) >= 1000
    assert time.monotonic() - t0 < 10 and time.process_time() - cpu0 < 10


@pytest.mark.proc
def test_the_real_command_in_a_terminal_starts_with_the_router_down_and_quits_on_q():
    """``pfp handheld`` in a pseudo-terminal, as a soldier starts it before the network is up."""
    import fcntl
    import os
    import select
    import struct
    import subprocess
    import sys
    import termios

    from tests.conftest import ROOT

    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 20, 60, 0, 0))
    env = {**os.environ, "TERM": "xterm-256color", "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "pfp_service", "handheld", "--unit", "tty1", "--goal", "10,0"]
    proc = subprocess.Popen(
        [*cmd, "--connect", f"tcp/127.0.0.1:{free_port()}"],
        stdin=slave, stdout=slave, stderr=slave, cwd=ROOT, env=env, close_fds=True,
    )  # fmt: skip
    os.close(slave)
    screen = b""

    def read_until(needle: bytes, timeout: float) -> bool:
        nonlocal screen
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    screen += os.read(master, 65536)
                except OSError:
                    return False
            if needle in screen:
                return True
        return False

    try:
        assert read_until(b"no router answers", 30), screen[-2000:]
        assert b"tty1" in screen
        os.write(master, b"q")
        assert proc.wait(timeout=15) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)


@pytest.mark.proc
def test_a_redraw_while_the_app_closes_ends_quietly(planner):  # noqa: F811 - the fixture imported above
    """The handheld's tick can fire while Textual removes its widgets: that draw stops, no NoMatches escapes."""
    endpoint, mission, _ = planner

    async def scenario():
        with open_link([endpoint], mission, "closing") as link:
            app = _app(link, mission, Settings(unit="closing", walk=False), start=(3.0, 4.0))
            async with app.run_test(size=SIZE) as pilot:
                await pilot.pause()
                await app.query_one("#arrow").remove()  # as the app's shutdown does, widget by widget
                app.redraw()  # the tick that lands meanwhile
                app.tick()
                app.exit()
            assert app.return_code == 0

    asyncio.run(scenario())
