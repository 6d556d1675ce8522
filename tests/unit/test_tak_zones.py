"""``pfp tak`` and keep-out zones: drawn shapes become zones, the planner's zones go to TAK as no-go shapes.

The unit tests read and build CoT with no network; the multi test runs taky, a
planner and the bridge, with a stand-in ATAK device drawing a polygon and
deleting it.
"""

from __future__ import annotations

import contextlib
import time
import xml.etree.ElementTree as ET

import msgspec
import pytest
from pfp_clients.tak import cot
from pfp_clients.tak.outputs import ZenohDelete, ZenohPut
from pfp_clients.tak.state import BridgeSettings, BridgeState

from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from pfp_service.world import translate

ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=87.5)
T0 = 1_700_000_000.0
# a square about 110 m a side, some 500 m north of the origin
SQUARE = [(58.4150, 15.6200), (58.4150, 15.6219), (58.4160, 15.6219), (58.4160, 15.6200)]


def shape(
    uid: str, typ: str, t: float, ttl: float, points=(), closed: str | None = None, radius=None
) -> bytes:
    """A drawn shape as ATAK sends it: vertices as ``<link point>``, a circle as ``<shape><ellipse>``."""
    lat, lon = points[0] if points else (58.4150, 15.6300)
    detail = "".join(f'<link point="{a},{b},87.5"/>' for a, b in points)
    if closed is not None:
        detail += f'<closed value="{closed}"/>'
    if radius is not None:
        detail += f'<shape><ellipse major="{radius}" minor="{radius}" angle="360"/></shape>'
    detail += '<strokeColor value="-1"/><contact callsign="drawn"/><remarks/>'
    return (
        f'<?xml version="1.0" encoding="UTF-8"?><event version="2.0" uid="{uid}" type="{typ}" '
        f'how="h-e" time="{cot.iso(t)}" start="{cot.iso(t)}" stale="{cot.iso(t + ttl)}">'
        f'<point lat="{lat}" lon="{lon}" hae="87.5" ce="9999999" le="9999999"/><detail>{detail}</detail></event>'
    ).encode()


def delete(target: str, t: float, typ: str = "u-d-f") -> bytes:
    return (
        f'<event version="2.0" uid="del-{target}" type="t-x-d-d" how="h-g-i-g-o" time="{cot.iso(t)}" '
        f'start="{cot.iso(t)}" stale="{cot.iso(t + 20)}"><point lat="0" lon="0" hae="0" ce="1" le="1"/>'
        f'<detail><link uid="{target}" relation="none" type="{typ}"/><__forcedelete/></detail></event>'
    ).encode()


def _state() -> BridgeState:
    return BridgeState(BridgeSettings(mission="m", origin=ORIGIN))


@pytest.mark.unit
@pytest.mark.parametrize(
    ("typ", "closed", "points"),
    [
        ("u-d-f", None, [*SQUARE, SQUARE[0]]),  # closed by repeating the first vertex
        ("u-d-f", "true", SQUARE),
        ("u-d-f", None, SQUARE),  # an area of three or more vertices, closed implicitly
        ("u-d-r", None, SQUARE),  # a rectangle's four corners
    ],
)
def test_a_drawn_polygon_or_rectangle_becomes_a_keep_out_zone(typ, closed, points):
    out = _state().on_cot(shape("ANDROID-1.poly", typ, T0, 600, points, closed), T0)
    (put,) = out.zenoh
    assert isinstance(put, ZenohPut) and put.key == keys.zone("m", cot.threat_id("ANDROID-1.poly"))
    z = m.decode_zone(put.payload)
    assert z.kind == "keep_out" and z.ttl_s == pytest.approx(600.0)
    assert z.polygon is not None and len(z.polygon[0]) == 5 and z.polygon[0][0] == z.polygon[0][-1]
    zone = translate.zone(z, "z")
    north, east = ORIGIN.localise_point(m.LatLon(lat=58.4155, lon=15.62095), "$")
    assert zone.contains(north, east) and not zone.contains(0.0, 0.0)


@pytest.mark.unit
def test_a_drawn_circle_becomes_a_circular_zone_and_an_ellipse_the_circle_covering_it():
    out = _state().on_cot(shape("c1", "u-d-c-c", T0, 600, radius=120.5), T0)
    z = m.decode_zone(out.zenoh[0].payload)  # type: ignore[union-attr]
    assert z.circle is not None and z.circle.radius_m == 120.5
    ev = cot.read_event(
        shape("c2", "u-d-c-c", T0, 600).replace(
            b"<strokeColor", b'<shape><ellipse major="50" minor="80"/></shape><strokeColor'
        )
    )
    assert ev.radius_m == 80.0


@pytest.mark.unit
def test_lines_our_own_shapes_and_stale_or_broken_shapes_make_no_zone():
    st = _state()
    line = [(58.4150, 15.6200), (58.4160, 15.6219)]
    assert not st.on_cot(shape("line", "u-d-f", T0, 600, line), T0).zenoh
    assert not st.on_cot(shape("open", "u-d-f", T0, 600, SQUARE, closed="false"), T0).zenoh
    assert not st.on_cot(shape("pfp.zone.m.z1", "u-d-f", T0, 600, SQUARE), T0).zenoh  # our echo
    bowtie = [SQUARE[0], SQUARE[2], SQUARE[1], SQUARE[3]]
    assert not st.on_cot(shape("bowtie", "u-d-f", T0, 600, bowtie), T0).zenoh  # crosses itself
    assert not st.on_cot(shape("nocircle", "u-d-c-c", T0, 600), T0).zenoh
    assert st.dropped == 2


@pytest.mark.unit
def test_a_shape_deleted_in_tak_deletes_its_zone_and_a_replay_does_not_bring_it_back():
    st = _state()
    (put,) = st.on_cot(shape("ANDROID-1.poly", "u-d-f", T0, 600, SQUARE), T0).zenoh
    (gone,) = st.on_cot(delete("ANDROID-1.poly", T0 + 5), T0 + 5).zenoh
    assert isinstance(gone, ZenohDelete) and gone.key == put.key  # type: ignore[union-attr]
    assert not st.on_cot(
        shape("ANDROID-1.poly", "u-d-f", T0, 600, SQUARE), T0 + 6
    ).zenoh  # the server's replay
    assert st.on_cot(shape("ANDROID-1.poly", "u-d-f", T0 + 7, 600, SQUARE), T0 + 7).zenoh  # drawn again


@pytest.mark.unit
def test_the_planners_zones_go_to_tak_as_red_no_go_shapes_and_their_delete_removes_them():
    st = _state()
    poly = m.ZoneUpdate(polygon=[[(0.0, 500.0), (100.0, 500.0), (100.0, 600.0), (0.0, 600.0), (0.0, 500.0)]])
    (data,) = st.on_zone(keys.zone("m", "mine"), m.encode(poly), T0).cot
    ev = ET.fromstring(data)
    assert ev.get("type") == "u-d-f" and ev.get("uid") == "pfp.zone.m.mine"
    assert ev.find("detail/remarks").text.startswith(cot.NO_GO_REMARK)  # type: ignore[union-attr]
    assert ev.find("detail/strokeColor").get("value") == str(cot.NO_GO_STROKE)  # type: ignore[union-attr]
    pts = [tuple(float(v) for v in ln.get("point").split(",")[:2]) for ln in ev.findall("detail/link")]  # type: ignore[union-attr]
    assert len(pts) == 5 and pts[0] == pts[-1]
    back = ORIGIN.localise_point(m.LatLon(lat=pts[1][0], lon=pts[1][1]), "$")
    assert back == pytest.approx((100.0, 500.0), abs=1e-3)
    circle = m.ZoneUpdate(circle=m.ZoneCircle(centre=(0.0, 0.0), radius_m=40.0))
    (data,) = st.on_zone(keys.zone("m", "round"), m.encode(circle), T0 + 1).cot
    ev = ET.fromstring(data)
    assert ev.get("type") == "u-d-c-c" and ev.find("detail/shape/ellipse").get("major") == "40.0"  # type: ignore[union-attr]
    assert len(st.picture(T0 + 2)) == 2
    (data,) = st.on_zone(keys.zone("m", "mine"), None, T0 + 3).cot
    ev = ET.fromstring(data)
    assert ev.get("type") == "t-x-d-d" and ev.find("detail/link").get("uid") == "pfp.zone.m.mine"  # type: ignore[union-attr]
    # a zone TAK drew is on the maps already: not sent back
    (put,) = st.on_cot(shape("ANDROID-1.poly", "u-d-f", T0, 600, SQUARE), T0 + 4).zenoh
    assert not st.on_zone(put.key, put.payload, T0 + 5).cot  # type: ignore[union-attr]


@pytest.mark.unit
def test_zones_a_planner_held_before_the_bridge_started_are_shown_unless_heard_since():
    st = _state()
    wall = m.ZoneUpdate(polygon=[[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 0.0)]])
    st.on_zone(keys.zone("m", "gone"), None, T0)  # deleted since the reply was made
    held = [
        m.ZoneSummary(id="wall", zone=wall),
        m.ZoneSummary(id="gone", zone=wall),
        m.ZoneSummary(id="soon", zone=msgspec.structs.replace(wall, ttl_s=600.0), ttl_s=5.0),
    ]
    out = st.on_zones_in_force(held, T0 + 1)
    assert sorted(ET.fromstring(d).get("uid") for d in out.cot) == ["pfp.zone.m.soon", "pfp.zone.m.wall"]
    assert set(st.zones) == {"wall", "soon"} and st.zones["soon"].ttl_s == 5.0  # the time left


@pytest.mark.multi
@pytest.mark.alone
def test_a_polygon_drawn_on_a_device_is_a_zone_within_a_second_and_its_delete_removes_it(tmp_path):
    pytest.importorskip("taky")
    from tests.multi.test_tak_taky import MISSION, device, running, taky_server
    from tests.multi.test_tak_taky import ORIGIN as TAKY_ORIGIN
    from tests.zenoh_util import Inbox, client, planner_process, put_in_force, put_json

    def zones_held(s) -> list[str]:
        for r in s.get(keys.worlds(MISSION), timeout=2.0):
            if r.ok is not None:
                return [z.id for z in m.decode_world_snapshot(r.ok.payload.to_bytes()).zones]
        return []

    def wait_held(s, want: list[str], timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while (got := zones_held(s)) != want:
            assert time.monotonic() < deadline, f"planner holds zones {got}, expected {want}"
            time.sleep(0.05)

    assert TAKY_ORIGIN == ORIGIN
    origin = f"{ORIGIN.lat},{ORIGIN.lon},{ORIGIN.alt}"
    with (
        contextlib.ExitStack() as stack,
        planner_process("--state-dir", "none", "--origin", origin, mission=MISSION) as (endpoint, _p),
        taky_server(tmp_path / "taky") as port,
        client(endpoint) as s,
        device(port, "ANDROID-stand-in-zones") as dev,
    ):
        # a zone the planner holds before the bridge starts reaches the device too
        put_in_force(
            s, MISSION, {keys.zone(MISSION, "early"): {"circle": {"centre": [0, -300], "radius_m": 30}}}
        )
        bridge = stack.enter_context(running(endpoint, port, tmp_path / "state"))
        bridge.wait_line("connected tcp://")
        _t, early = dev.wait(lambda e: e.get("uid") == f"pfp.zone.{MISSION}.early", timeout=15)
        assert early.get("type") == "u-d-c-c"
        uid = "ANDROID-stand-in-zones.poly1"
        zid = cot.threat_id(uid)
        inbox = Inbox(s, keys.zone(MISSION, zid))
        t0 = time.monotonic()
        dev.send(shape(uid, "u-d-f", time.time(), 3600, [*SQUARE, SQUARE[0]]))
        body = inbox.get(timeout=10, where=lambda msg: msg is not None)
        wait_held(s, sorted(["early", zid]))
        took = time.monotonic() - t0
        print(f"drawn polygon -> zone held by the planner in {took * 1e3:.0f} ms")
        assert took < 1.0, f"{took:.2f} s from the drawing to the planner"
        assert body["kind"] == "keep_out" and len(body["polygon"][0]) == 5
        t0 = time.monotonic()
        dev.send(delete(uid, time.time()))
        inbox.get(timeout=10, where=lambda msg: msg is None)
        wait_held(s, ["early"])
        print(
            f"deleted on the device -> zone gone from the planner in {(time.monotonic() - t0) * 1e3:.0f} ms"
        )
        # and the planner's own zone reaches the device as a red no-go shape
        put_json(s, keys.zone(MISSION, "from-planner"), {"circle": {"centre": [0, 300], "radius_m": 50}})
        _t, ev = dev.wait(lambda e: e.get("uid") == f"pfp.zone.{MISSION}.from-planner", timeout=15)
        assert ev.get("type") == "u-d-c-c"
        assert (ev.find("detail/remarks").text or "").startswith(cot.NO_GO_REMARK)  # type: ignore[union-attr]
