"""``pfp handheld``: the sans-I/O model, and the Textual app driven by its pilot against a real planner."""

from __future__ import annotations

import asyncio
import math
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import msgspec
import pytest
from pfp_clients.handheld import HandheldApp
from pfp_clients.handheld_link import open_link
from pfp_clients.handheld_model import (
    CARDINALS,
    HandheldModel,
    Settings,
    Severity,
    arrow_art,
    bearing_text,
    cardinal,
    eta_s,
    format_duration,
)
from pfp_clients.nmea import LocalFrame
from pfp_clients.nmea_feed import NmeaReader, open_nmea

from pfp_service.wire import GOAL_CANCELLED, Direction, DirectionStatus, GoalMobility, keys
from tests.conftest import run_pfp
from tests.zenoh_util import Inbox, client, free_port, planner_process, put_json

SIZE = (50, 20)


# -- the model, no network ------------------------------------------------------------
def _direction(status="en_route", vector=(1.0, 0.0), distance=10.0, level=0.0, unit="u1") -> Direction:
    heading = math.degrees(math.atan2(*vector)) % 360 if vector != (0.0, 0.0) else None
    return Direction(
        unit=unit,
        status=DirectionStatus(status),
        vector=vector,
        heading_deg=heading,
        distance_to_goal=distance,
        threat_level=level,
    )


@pytest.mark.unit
@pytest.mark.parametrize(
    ("bearing", "name"),
    [
        (0, "N"),
        (11.24, "N"),
        (11.25, "NNE"),
        (45, "NE"),
        (90, "E"),
        (135, "SE"),
        (180, "S"),
        (202.5, "SSW"),
        (247.5, "WSW"),
        (270, "W"),
        (348.74, "NNW"),
        (348.75, "N"),
        (359.9, "N"),
        (360, "N"),
        (-90, "W"),
        (720 + 22.5, "NNE"),
    ],
)
def test_cardinal(bearing, name):
    assert cardinal(bearing) == name


@pytest.mark.unit
def test_sixteen_points_in_order():
    assert [cardinal(i * 22.5) for i in range(16)] == list(CARDINALS)
    assert bearing_text(359.6) == "000° N"
    assert bearing_text(47.2) == "047° NE"
    assert bearing_text(None) == "---° --"


@pytest.mark.unit
def test_eta_and_durations():
    assert eta_s(14.0, 1.4) == pytest.approx(10.0)
    assert eta_s(None, 1.4) is None
    assert eta_s(5.0, 0.0) is None
    assert [format_duration(s) for s in (None, 0.4, 9, 59.6, 185, 3725)] == [
        "--",
        "0 s",
        "9 s",
        "1 min 00 s",
        "3 min 05 s",
        "1 h 02 min",
    ]


def _pixels(lines: list[str]) -> list[tuple[float, float]]:
    """Centres of the filled half-cell pixels, in pixels from the picture's centre (x east, y north)."""
    pts = []
    half_w, half_h = len(lines[0]) / 2, len(lines)
    for r, line in enumerate(lines):
        for c, ch in enumerate(line):
            if ch in "█▀":
                pts.append((c + 0.5 - half_w, half_h - (2 * r + 0.5)))
            if ch in "█▄":
                pts.append((c + 0.5 - half_w, half_h - (2 * r + 1.5)))
    return pts


def _reach(lines: list[str], bearing_deg: float) -> float:
    """How far the picture reaches along a compass bearing."""
    s, c = math.sin(math.radians(bearing_deg)), math.cos(math.radians(bearing_deg))
    return max(x * s + y * c for x, y in _pixels(lines))


def _points_along(lines: list[str], bearing_deg: float, margin: float = 0.3) -> bool:
    """The arrow reaches farther along ``bearing_deg`` than behind it or to either side."""
    ahead = _reach(lines, bearing_deg)
    return all(ahead > _reach(lines, bearing_deg + off) + margin for off in (90, 180, 270))


@pytest.mark.unit
@pytest.mark.parametrize("size", [(19, 9), (23, 11), (31, 15)])
def test_arrow_points_along_the_bearing(size):
    for bearing in range(360):
        lines = arrow_art(bearing, *size)
        assert len(lines) == size[1] and {len(line) for line in lines} == {size[0]}
        assert _points_along(lines, bearing, margin=0.2), bearing  # (coarser pictures may tie)


@pytest.mark.unit
def test_arrow_without_bearing_shows_the_status():
    ring, cross, dot = (arrow_art(None, status=s) for s in ("arrived", "trapped", "no_goal"))
    assert len({"\n".join(ring), "\n".join(cross), "\n".join(dot)}) == 3
    assert sum(line.count("█") for line in dot) < sum(line.count("█") for line in ring)


@pytest.mark.unit
def test_staleness_uses_the_given_clock():
    m = HandheldModel(Settings(unit="u1", stale_after_s=2.0), (0.0, 0.0), now=100.0)
    v = m.view(101.0)
    assert (v.age_s, v.stale, v.status_label) == (None, False, "WAITING FOR PLANNER")
    assert m.view(102.5).stale  # nothing ever came
    m.on_direction(_direction(), now=103.0)
    assert not m.view(104.9).stale
    assert m.view(104.9).age_s == pytest.approx(1.9)
    assert m.view(105.1).stale


@pytest.mark.unit
def test_walk_follows_the_direction_and_stops_at_the_goal():
    m = HandheldModel(Settings(unit="u1", speed_mps=2.0, stale_after_s=100.0), (0.0, 0.0), now=0.0)
    m.on_direction(_direction(vector=(0.0, 1.0), distance=3.0), now=0.0)
    m.advance(1.0)
    assert m.position == pytest.approx((0.0, 2.0))
    assert m.heading_deg == pytest.approx(0.0) and m.speed_mps == pytest.approx(2.0)
    assert m.view(1.0).distance_m == pytest.approx(1.0)
    assert m.view(1.0).eta_s == pytest.approx(0.5)
    m.advance(5.0)  # would be 8 m more: clamped to the goal the planner reported
    assert m.position == pytest.approx((0.0, 3.0))
    m.on_direction(_direction(status="arrived", vector=(0.0, 0.0), distance=0.0), now=5.0)
    m.advance(9.0)
    assert m.position == pytest.approx((0.0, 3.0)) and m.speed_mps == 0.0
    assert m.view(9.0).status_label == "ARRIVED" and m.view(9.0).bearing == "---° --"


@pytest.mark.unit
def test_walk_halts_when_guidance_is_stale_or_paused():
    m = HandheldModel(Settings(unit="u1", speed_mps=1.0, stale_after_s=1.0), (0.0, 0.0), now=0.0)
    m.on_direction(_direction(vector=(1.0, 0.0), distance=100.0), now=0.0)
    m.advance(0.5)
    assert m.position == pytest.approx((0.5, 0.0))
    m.advance(3.0)  # stale by now: a soldier is not walked off on old guidance
    assert m.position == pytest.approx((0.5, 0.0))
    m.on_direction(_direction(vector=(1.0, 0.0), distance=100.0), now=3.0)
    m.toggle_walk(3.0)
    m.advance(3.5)
    assert m.position == pytest.approx((0.5, 0.0))


@pytest.mark.unit
def test_states_carry_seq_kind_speed_heading():
    m = HandheldModel(Settings(unit="u1"), (1.0, 2.0), now=0.0)
    m.nudge(0.0, -1.0)
    s1, s2 = m.next_state(t=1e9), m.next_state()
    assert (s1.seq, s2.seq) == (1, 2)
    assert s1.position == (1.0, 1.0) and s1.kind == "manned" and s1.heading_deg == pytest.approx(180.0)
    assert s1.t == 1e9 and s1.speed_mps == 0.0
    assert s1.mobility == s2.mobility == GoalMobility(kind="foot")  # a soldier's slopes, on every state
    assert HandheldModel(Settings(unit="u1"), None, now=0.0).next_state() is None


@pytest.mark.unit
def test_gps_fix_gives_speed_and_heading():
    m = HandheldModel(Settings(unit="u1", walk=False), None, now=0.0)
    m.on_fix(0.0, 0.0, now=0.0)
    m.on_fix(3.0, 3.0, now=2.0)
    assert m.speed_mps == pytest.approx(math.hypot(3, 3) / 2)
    assert m.heading_deg == pytest.approx(45.0)
    m.on_fix(3.1, 3.0, now=3.0)  # GPS jitter: keep the heading
    assert m.heading_deg == pytest.approx(45.0)


@pytest.mark.unit
def test_goal_is_resent_until_acted_on_then_left_alone():
    m = HandheldModel(Settings(unit="u1", goal=(5.0, 5.0), goal_retry_s=2.0), (0.0, 0.0), now=0.0)
    assert m.goal_to_send(0.0).position == (5.0, 5.0)
    assert m.goal_to_send(1.0) is None
    m.on_direction(_direction(status="no_goal", vector=(0.0, 0.0), distance=None), now=1.5)
    assert m.goal_to_send(2.5) is not None  # the planner missed it (restarted, raced): again
    m.on_direction(_direction(), now=3.0)
    assert m.goal_to_send(6.0) is None  # acted on: left alone
    m.on_direction(_direction(status="no_goal", vector=(0.0, 0.0), distance=None), now=7.0)
    assert m.goal_to_send(7.5) is not None  # the planner lost it (a restart): again
    m.on_direction(_direction(), now=8.0)
    m.on_planner_up()  # a new planner's token: it knows nothing of our goal
    assert m.goal_to_send(8.1) is not None
    m.on_direction(_direction(), now=8.5)
    m.on_goal(None)  # somebody cancelled it on the wire: respect that
    m.on_direction(_direction(status="no_goal", vector=(0.0, 0.0), distance=None), now=9.0)
    assert m.goal_to_send(20.0) is None
    m.set_goal((7.0, 1.0))  # the g prompt
    assert m.goal_to_send(20.1).position == (7.0, 1.0)


@pytest.mark.unit
def test_a_no_goal_that_says_cancelled_is_not_answered_with_the_goal_again():
    # the planner saw a delete; its direction may reach us before the delete's own sample does
    m = HandheldModel(Settings(unit="u1", goal=(5.0, 5.0), goal_retry_s=2.0), (0.0, 0.0), now=0.0)
    assert m.goal_to_send(0.0) is not None
    m.on_direction(_direction(), now=0.5)
    cancelled = msgspec.structs.replace(
        _direction(status="no_goal", vector=(0.0, 0.0), distance=None), reason=GOAL_CANCELLED
    )
    m.on_direction(cancelled, now=1.0)
    assert m.goal_to_send(5.0) is None
    m.on_goal(None)  # the delete's sample, later
    assert m.goal is None and m.goal_to_send(9.0) is None


@pytest.mark.unit
def test_threat_severity_and_bad_direction_note():
    m = HandheldModel(Settings(unit="u1", threat_full_scale=2.0), (0.0, 0.0), now=0.0)
    for level, sev in (
        (0.1, Severity.LOW),
        (0.8, Severity.CAUTION),
        (1.5, Severity.DANGER),
        (9, Severity.DANGER),
    ):
        m.on_direction(_direction(level=level), now=0.0)
        v = m.view(0.0)
        assert v.severity is sev and v.threat_fraction == pytest.approx(min(level / 2.0, 1.0))
    m.on_rejected("$.vector: expected array")
    assert "bad direction" in m.view(0.0).note and m.view(0.0).threat_level == 9


# -- the app against a real planner ------------------------------------------------
@pytest.fixture(scope="module")
def planner():
    mission = "h" + uuid.uuid4().hex[:10]
    with planner_process(mission=mission) as (endpoint, proc):
        yield endpoint, mission, proc


async def _until(pilot, pred: Callable[[], object], what: str, timeout: float = 10.0):
    deadline = time.monotonic() + timeout
    while not (value := pred()):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await pilot.pause(0.05)
    return value


async def _next_msg(pilot, inbox: Inbox, where: Callable[[dict], bool], what: str, timeout: float = 10.0):
    def poll():
        while not inbox.q.empty():
            _key, msg = inbox.q.get_nowait()
            if msg is not None and where(msg):
                return msg
        return None

    return await _until(pilot, poll, what, timeout)


def _text(app: HandheldApp, wid: str) -> str:
    return str(app.query_one(f"#{wid}").content)


def _app(link, mission: str, settings: Settings, **kw) -> HandheldApp:
    model = HandheldModel(settings, kw.pop("start", (0.0, 0.0)), time.monotonic())
    return HandheldApp(model, link, mission=mission, publish_hz=5.0, **kw)


@pytest.mark.proc
def test_arrow_and_bearing_follow_the_planner(planner, tmp_path: Path):
    endpoint, mission, _ = planner
    uid = "arrow"

    async def scenario():
        settings = Settings(unit=uid, walk=False, goal=(20.0, 0.0))
        with open_link([endpoint], mission, uid) as link, client(endpoint) as s:
            app = _app(link, mission, settings)
            async with app.run_test(size=SIZE) as pilot:
                await _until(pilot, lambda: app.last_view.bearing == "090° E", "a bearing east")
                east_arrow = _text(app, "arrow")
                assert len(east_arrow.splitlines()) >= 9  # the arrow is the biggest thing on 50x20
                assert _text(app, "bearing") == "090° E"
                assert _text(app, "status") == "EN ROUTE  holding"  # not walking: it says speed 0
                assert _text(app, "nav").startswith("Dist 20.0 m  ETA 14 s")
                assert _points_along(east_arrow.splitlines(), 90)

                put_json(s, keys.unit_goal(mission, uid), {"position": [0.0, 20.0]})
                await _until(pilot, lambda: app.last_view.bearing == "000° N", "a bearing north")
                north_arrow = _text(app, "arrow")
                assert north_arrow != east_arrow
                assert _points_along(north_arrow.splitlines(), 0)

                # a threat just north-east of the unit bends the direction away, to the west
                threat = {"position": [1.0, 1.5], "sigma_range": 1.5, "sigma_lateral": 1.5}
                put_json(s, keys.threat(mission, "t-arrow"), threat)
                view = await _until(
                    pilot,
                    lambda: app.last_view if app.last_view.bearing_deg not in (None, 0.0) else None,
                    "a bent bearing",
                )
                assert 180 < view.bearing_deg < 350, view
                assert view.threat_level > 0.1
                assert _text(app, "bearing") == view.bearing
                assert _text(app, "arrow") not in (north_arrow, east_arrow)

                # everything fits on a 50x20 screen
                for wid in ("title", "arrow", "bearing", "status", "nav", "threat", "age", "pos", "keys"):
                    region = app.query_one(f"#{wid}").region
                    assert region.height >= 1 and region.bottom <= SIZE[1] and region.right <= SIZE[0], wid
                assert view.bearing in _text(app, "bearing")
                assert "Threat" in _text(app, "threat")

                shot = Path(app.save_screenshot("handheld.svg", str(tmp_path)))
                assert shot.exists()
                svg = shot.read_text()
                assert view.bearing.replace(" ", "&#160;") in svg
                assert "Updated" in svg
            s.delete(keys.threat(mission, "t-arrow"))

    asyncio.run(scenario())


@pytest.mark.proc
def test_arrow_keys_nudge_the_published_position(planner):
    endpoint, mission, _ = planner
    uid = "nudge"

    async def scenario():
        with client(endpoint) as s:
            states = Inbox(s, keys.shard_state(mission, uid))  # the handheld publishes on its shard
            directions = Inbox(s, keys.unit_direction(mission, uid))
            with open_link([endpoint], mission, uid) as link:
                app = _app(link, mission, Settings(unit=uid, walk=False, nudge_m=0.5), start=(3.0, 4.0))
                async with app.run_test(size=SIZE) as pilot:
                    first = await _next_msg(pilot, states, lambda m: True, "a first state")
                    assert first["position"] == [3.0, 4.0] and first["kind"] == "manned"
                    await pilot.press("right", "right", "up")
                    moved = await _next_msg(
                        pilot, states, lambda m: m["position"] == [4.0, 4.5], "the nudged position"
                    )
                    assert moved["heading_deg"] == 0.0 and moved["seq"] > first["seq"]
                    # the planner answers the nudged state, echoing its seq
                    await _next_msg(pilot, directions, lambda d: d["seq"] == moved["seq"], "its direction")
                    await pilot.press("left")
                    back = await _next_msg(pilot, states, lambda m: m["position"] == [3.5, 4.5], "west")
                    assert back["heading_deg"] == 270.0
                    assert app.last_view.position == (3.5, 4.5)
                    assert _alive(s, mission) == {keys.alive_unit(mission, uid)}
            assert _alive(s, mission) == set()  # the token went with the closed session

    asyncio.run(scenario())


def _alive(session, mission: str) -> set[str]:
    replies = session.liveliness().get(keys.alive_units(mission), timeout=2.0)
    return {str(r.ok.key_expr) for r in replies if r.ok is not None}


@pytest.mark.proc
def test_nmea_file_drives_the_position(planner, tmp_path: Path):
    endpoint, mission, _ = planner
    uid = "gps"
    frame = LocalFrame(48.0, 11.0)
    lat, lon = frame.to_geodetic(25.0, -40.0)
    lat_min, lon_min = (abs(lat) - int(abs(lat))) * 60, (abs(lon) - int(abs(lon))) * 60
    body = f"GPGGA,101010.00,{int(lat):02d}{lat_min:08.5f},N,{int(lon):03d}{lon_min:08.5f},E,1,09,0.8,500.0,M,47.0,M,,"
    good = f"${body}*{_xor(body):02X}"
    no_fix = (
        "$GPGGA,101009.00,,,,,0,00,99.9,,M,,M,,*" + f"{_xor('GPGGA,101009.00,,,,,0,00,99.9,,M,,M,,'):02X}"
    )
    nmea = tmp_path / "track.nmea"
    nmea.write_bytes(("\r\n".join([no_fix, good.replace(",E,", ",W,"), "not nmea", good]) + "\r\n").encode())

    async def scenario():
        with client(endpoint) as s:
            states = Inbox(s, keys.shard_state(mission, uid))  # the handheld publishes on its shard
            with open_link([endpoint], mission, uid) as link:
                reader = NmeaReader(open_nmea(str(nmea)), frame, link.inbox)
                app = _app(
                    link, mission, Settings(unit=uid, walk=False), start=None, source="nmea", nmea=reader
                )
                async with app.run_test(size=SIZE) as pilot:
                    state = await _next_msg(pilot, states, lambda m: True, "a state from the fix")
                    x, y = state["position"]
                    # 5 decimal places of minutes: about 2 cm
                    assert (x, y) == pytest.approx((25.0, -40.0), abs=0.03)
                    await _until(pilot, lambda: "stream ended" in app.last_view.note, "the end of the file")
                    assert app.model.counts == {
                        "directions": app.model.counts["directions"],
                        "rejected": 0,
                        "fixes": 1,
                        "no_fix": 1,
                        "nmea_rejected": 2,  # the sentence with a flipped hemisphere, and "not nmea"
                    }
                    assert "GPS" in _text(app, "title")

    asyncio.run(scenario())


def _xor(body: str) -> int:
    value = 0
    for b in body.encode():
        value ^= b
    return value


@pytest.mark.proc
def test_stale_warning_when_the_planner_goes_quiet(tmp_path: Path):
    mission = "s" + uuid.uuid4().hex[:10]
    uid = "stale"

    async def scenario(endpoint, proc):
        with open_link([endpoint], mission, uid) as link:
            app = _app(link, mission, Settings(unit=uid, stale_after_s=1.0, goal=(5.0, 5.0)))
            async with app.run_test(size=SIZE) as pilot:
                await _until(pilot, lambda: app.last_view.status_label == "EN ROUTE", "guidance")
                assert _text(app, "age").strip().startswith("Updated")
                assert not app.last_view.stale
                proc.terminate()  # the planner dies: no more directions
                proc.wait(timeout=10)
                await _until(pilot, lambda: "STALE" in _text(app, "age"), "the stale warning", timeout=5)
                assert app.last_view.age_s > 1.0
                walked = app.model.position
                await pilot.pause(0.3)
                assert app.model.position == walked  # no walking on stale guidance
                svg = Path(app.save_screenshot("stale.svg", str(tmp_path))).read_text()
                assert "STALE" in svg

    with planner_process(mission=mission) as (endpoint, proc):
        asyncio.run(scenario(endpoint, proc))


# -- the command line ------------------------------------------------------------------
@pytest.mark.proc
def test_cli_errors_are_one_line():
    r = run_pfp("handheld", "--unit", "u1", "--nmea", "-")
    assert r.returncode == 2 and r.stderr.strip() == (
        "pfp handheld: --origin: required with --nmea (the LAT,LON of the planner's 0,0)"
    )
    r = run_pfp("handheld", "--unit", "u1", "--origin", "48,north")
    assert r.returncode == 2 and "LAT,LON" in r.stderr and "Traceback" not in r.stderr
    r = run_pfp("handheld", "--unit", "u1", "--origin", "48,11")
    assert r.returncode == 2 and r.stderr.strip() == "pfp handheld: --origin: only goes with --nmea"
    r = run_pfp("handheld", "--unit", "u1", "--connect", "notanendpoint")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.proc
def test_refuses_to_start_without_a_terminal():
    """A pipe on stdout would get escape codes: one line instead, and nothing drawn."""
    r = run_pfp("handheld", "--unit", "u1", "--connect", f"tcp/127.0.0.1:{free_port()}")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip() == (
        "pfp handheld: needs a terminal: stdout is not one (it is a terminal UI; run it in a terminal)"
    )
