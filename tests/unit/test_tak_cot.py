"""Cursor-on-Target in and out, and the bridge's state machine, without a socket."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import pytest
from pfp_clients.tak import cot, cot_out
from pfp_clients.tak.outputs import ZenohDelete, ZenohPut
from pfp_clients.tak.state import BridgeSettings, BridgeState

from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m

pytestmark = pytest.mark.unit

ORIGIN = Origin(lat=58.4105, lon=15.6213)
T0 = 1_796_000_000.0  # a fixed clock: nothing here reads the real one


def hostile(
    uid="ANDROID-7f.h1", typ="a-h-G-U-C", lat=58.4150, lon=15.6300, ttl=600, course="225", t=T0
) -> bytes:
    track = f'<track course="{course}" speed="0"/>' if course is not None else ""
    return (
        f'<?xml version="1.0"?><event version="2.0" uid="{uid}" type="{typ}" how="h-g-i-g-o" '
        f'time="{cot.iso(t)}" start="{cot.iso(t)}" stale="{cot.iso(t + ttl)}">'
        f'<point lat="{lat}" lon="{lon}" hae="0" ce="9999999" le="9999999"/>'
        f'<detail>{track}<contact callsign="H1"/></detail></event>'
    ).encode()


def delete(target: str, t=T0) -> bytes:
    return (
        f'<event version="2.0" uid="del-1" type="t-x-d-d" how="h-g-i-g-o" time="{cot.iso(t)}" '
        f'start="{cot.iso(t)}" stale="{cot.iso(t + 20)}"><point lat="0" lon="0" hae="0" ce="1" le="1"/>'
        f'<detail><link uid="{target}" relation="none" type="a-h-G"/><__forcedelete/></detail></event>'
    ).encode()


def test_a_hostile_marker_becomes_a_threat():
    ev = cot.read_event(hostile())
    assert (ev.uid, ev.type, ev.course_deg, ev.callsign) == ("ANDROID-7f.h1", "a-h-G-U-C", 225.0, "H1")
    change = cot.to_threat_change(ev, cot.ThreatDefaults(sigma_range_m=80, sigma_lateral_m=40, skew=1), T0)
    assert isinstance(change, cot.ThreatPut)
    assert change.id == cot.threat_id("ANDROID-7f.h1") and change.id.startswith("ANDROID-7f_h1-")
    assert change.body["ttl_s"] == pytest.approx(600.0)
    assert change.body["facing_deg"] == 225.0 and change.body["sigma_range"] == 80
    assert change.body["position"] == {"lat": 58.415, "lon": 15.63}


def test_uids_map_to_ids_stably_and_valid_ones_unchanged():
    assert cot.threat_id("3f2c9a1e-77aa-4d1b-9b0e-1c2d3e4f5a6b") == "3f2c9a1e-77aa-4d1b-9b0e-1c2d3e4f5a6b"
    a, b = cot.threat_id("x.y"), cot.threat_id("x_y")
    assert a != b and a == cot.threat_id("x.y") and b == "x_y"
    long = cot.threat_id("u" * 200)
    assert len(long) <= 64 and keys.check_chunk(long)


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        (b"<event", "not XML"),
        (b"not xml at all", "not XML"),
        (b"<foo/>", "expected <event>"),
        (b'<event uid="a" type="a-h-G"/>', "<point> is required"),
        (hostile().replace(b'lat="58.415"', b'lat="95"'), "point.lat"),
        (hostile().replace(b'lon="15.63"', b'lon="east"'), "point.lon: not a number"),
        (hostile(course="north"), "track.course"),
        (hostile().replace(b'time="', b'time="yesterday'), "event.time"),
        (b'<!DOCTYPE x [<!ENTITY a "aaaa">]><event uid="a" type="b"/>', "DTD"),
        (b"<event>" + b" " * (cot.MAX_EVENT_BYTES + 1) + b"</event>", "exceeds"),
    ],
)
def test_bad_cot_is_a_cot_error_with_a_reason(data, fragment):
    with pytest.raises(cot.CotError, match=fragment):
        cot.read_event(data)


def test_deletes_stale_markers_and_other_types():
    d = cot.ThreatDefaults()
    assert cot.to_threat_change(cot.read_event(delete("ANDROID-7f.h1")), d, T0) == cot.ThreatRemoved(
        id=cot.threat_id("ANDROID-7f.h1"), uid="ANDROID-7f.h1"
    )
    assert isinstance(cot.to_threat_change(cot.read_event(hostile(ttl=0)), d, T0), cot.ThreatRemoved)
    assert cot.to_threat_change(cot.read_event(hostile(typ="a-f-G-U-C")), d, T0) is None  # friendly
    assert cot.to_threat_change(cot.read_event(hostile(typ="a-h-A")), d, T0) is None  # hostile air
    assert (
        cot.to_threat_change(cot.read_event(hostile(uid="pfp.threat.default.x")), d, T0) is None
    )  # our echo
    no_course = cot.to_threat_change(
        cot.read_event(hostile(course=None)), cot.ThreatDefaults(facing_deg=90), T0
    )
    assert isinstance(no_course, cot.ThreatPut) and no_course.body["facing_deg"] == 90


def test_outbound_points_keep_full_precision():
    lat, lon = 58.41234567891234, 15.62345678912345
    ev = ET.fromstring(cot_out.threat_event("pfp.threat.m.a", lat, lon, T0, 60, 225.0, "r", "threat a"))
    p = ev.find("point")
    assert p is not None and float(p.get("lat")) == lat and float(p.get("lon")) == lon
    assert ev.get("type") == "a-h-G" and ev.find("detail/track").get("course") == "225.0"
    back = cot.read_event(cot_out.threat_event("pfp.threat.m.a", lat, lon, T0, 60, 0.0, "r", "c"))
    assert back.stale - back.time == pytest.approx(60.0)


def test_route_links_are_ordered_waypoints_and_control_points():
    pts = [(58.41, 15.62), (58.411, 15.621), (58.412, 15.6225), (58.413, 15.624)]
    ev = ET.fromstring(cot_out.route_event("pfp.route.m.u1", pts, T0, 90, "route u1", "x"))
    assert ev.get("type") == "b-m-r"
    links = ev.findall("detail/link")
    assert [lk.get("type") for lk in links] == ["b-m-p-w", "b-m-p-c", "b-m-p-c", "b-m-p-w"]
    got = [tuple(float(v) for v in lk.get("point").split(",")[:2]) for lk in links]
    assert got == pts
    with pytest.raises(ValueError):
        cot_out.route_event("r", pts[:1], T0, 90, "", "")


def test_unit_markers_by_kind():
    manned = ET.fromstring(cot_out.unit_event("u", True, 1.0, 2.0, T0, 30, 45.5, 1.5, "pfp en_route", "m1"))
    robot = ET.fromstring(cot_out.unit_event("u", False, 1.0, 2.0, T0, 30, None, 0.0, "pfp arrived", "r1"))
    assert manned.get("type") == "a-f-G-U-C" and robot.get("type") == "a-f-G-E-V"
    assert manned.find("detail/track").get("course") == "45.5" and robot.find("detail/track") is None
    assert manned.find("detail/remarks").text == "pfp en_route"


def test_rate_limiter_holds_back_and_sends_the_latest():
    rl = cot_out.RateLimiter(1.0)
    assert rl.offer("a", b"1", 0.0) == [b"1"]
    assert rl.offer("a", b"2", 0.3) == [] and rl.offer("a", b"3", 0.6) == []
    assert rl.offer("b", b"x", 0.6) == [b"x"]  # per uid
    assert rl.due(0.9) == [] and rl.due(1.0) == [b"3"] and rl.held == 0
    assert rl.offer("a", b"4", 1.5) == [] and rl.due(2.0) == [b"4"]


# -- the state machine -----------------------------------------------------------------
def _state(**kw) -> BridgeState:
    return BridgeState(BridgeSettings(mission="m", origin=ORIGIN, rate_s=1.0, **kw))


def test_state_puts_and_removes_a_tak_threat_and_does_not_echo_it():
    s, logs = _state(), []
    s.log = logs.append
    out = s.on_cot(hostile(), T0)
    (put,) = out.zenoh
    assert isinstance(put, ZenohPut) and put.key == keys.threat("m", cot.threat_id("ANDROID-7f.h1"))
    t = m.decode_threat(put.payload)
    assert t.position == pytest.approx(ORIGIN.to_local(58.415, 15.63), abs=1e-6) and t.ttl_s == 600
    assert s.on_threat(put.key, put.payload, T0).cot == []  # the planner's echo of TAK's marker
    (gone,) = s.on_cot(delete("ANDROID-7f.h1"), T0 + 1).zenoh
    assert gone == ZenohDelete(put.key)
    assert s.on_cot(delete("ANDROID-7f.h1"), T0 + 2).zenoh == []  # already gone
    assert s.on_cot(b"<event", T0).zenoh == [] and s.dropped == 1 and "not XML" in logs[-1]
    far = s.on_cot(hostile(uid="far", lat=60.0), T0)
    assert far.zenoh == [] and "from the mission origin" in logs[-1]


def test_state_sends_planner_threats_rate_limited_and_deletes_them():
    s = _state()
    key = keys.threat("m", "ambush")
    body = m.encode(m.ThreatUpdate(position=(100.0, 200.0), sigma_range=5, sigma_lateral=3, facing_deg=90))
    (first,) = s.on_threat(key, body, T0).cot
    ev = cot.read_event(first)
    assert ev.uid == "pfp.threat.m.ambush" and ev.type == "a-h-G" and ev.course_deg == 90.0
    assert ORIGIN.to_local(ev.lat, ev.lon) == pytest.approx((100.0, 200.0), abs=1e-6)
    assert s.on_threat(key, body, T0 + 0.2).cot == []  # held back
    assert len(s.tick(T0 + 1.0).cot) >= 1
    (rm,) = s.on_threat(key, None, T0 + 5).cot
    assert cot.read_event(rm).type == "t-x-d-d" and cot.read_event(rm).link_uids == ("pfp.threat.m.ambush",)


def test_state_unit_marker_route_requests_and_routes():
    s = _state(route_points=5)
    state = m.encode(m.UnitState(position=(0.0, 0.0), kind=m.UnitKind.MANNED, speed_mps=1.5))
    s.on_state(keys.unit_state("m", "u1"), state)
    d = m.Direction(unit="u1", status=m.DirectionStatus.EN_ROUTE, vector=(0.0, 1.0), distance_to_goal=100.0)
    out = s.on_direction(keys.unit_direction("m", "u1"), m.encode(d), T0)
    (marker,) = out.cot
    ev = cot.read_event(marker)
    assert ev.type == "a-f-G-U-C" and ev.course_deg == pytest.approx(0.0, abs=1e-9)
    assert ET.fromstring(marker).find("detail/remarks").text.startswith("pfp en_route; 100 m to goal")
    assert out.routes == ["u1"]
    assert s.on_direction(keys.unit_direction("m", "u1"), m.encode(d), T0 + 0.5).routes == []  # same status
    path = [(0.0, float(y)) for y in range(0, 101, 5)]
    (route,) = s.on_route("u1", path, "reached", 100.0, T0 + 2).cot
    links = ET.fromstring(route).findall("detail/link")
    assert len(links) == 5
    ys = [ORIGIN.to_local(*map(float, lk.get("point").split(",")[:2]))[1] for lk in links]
    assert (
        ys == sorted(ys)
        and ys[0] == pytest.approx(0.0, abs=1e-6)
        and ys[-1] == pytest.approx(100.0, abs=1e-6)
    )
    assert s.on_route("u1", path, "reached", 100.0, T0 + 5).cot == []  # unchanged: not sent again
    replan = m.encode(m.ReplanEvent(units=["u1"], reason="threat put"))
    assert s.on_event(replan, T0 + 2.5).routes == ["u1"]
    assert s.on_event(replan, T0 + 3.0).routes == []  # too soon: asked once the interval is over
    assert s.tick(T0 + 4.6).routes == ["u1"]


def test_a_threat_in_plain_json_gives_cot_bytes():
    s = _state()
    out = s.on_threat(
        keys.threat("m", "a"),
        json.dumps({"position": [1, 2], "sigma_range": 1, "sigma_lateral": 1}).encode(),
        T0,
    )
    assert all(isinstance(b, bytes) for b in out.cot)
