"""The TAK link's field faults, in process: bounded framing, tombstones, TTL from now, pictures, hae."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pfp_clients.tak import cot
from pfp_clients.tak.framing import EventFramer
from pfp_clients.tak.outputs import ZenohDelete, ZenohPut
from pfp_clients.tak.state import BridgeSettings, BridgeState, Tombstone

from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from tests.unit.test_tak_cot import T0, delete, hostile

pytestmark = pytest.mark.unit

ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=123.5)
LIMIT = 4096


def _feed_all(framer: EventFramer, chunks: list[bytes]) -> tuple[list[bytes], list[int]]:
    events: list[bytes] = []
    skipped: list[int] = []
    for c in chunks:
        got = framer.feed(c)
        events += got.events
        skipped += got.skipped_bytes
    return events, skipped


def _chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    return [data[a:b] for a, b in zip(points, points[1:], strict=False)]


# -- framing ---------------------------------------------------------------------------
def test_framer_splits_a_stream_of_documents():
    a, b = hostile(uid="a"), hostile(uid="b")
    stream = a + b"\n  garbage  " + b + b'<eventual x="1"/>' + b'<event uid="c" type="t"/>'
    events, skipped = _feed_all(EventFramer(LIMIT), [stream])
    assert skipped == []
    assert [cot.read_event(e).uid for e in events[:2]] == ["a", "b"]
    assert events[2] == b'<event uid="c" type="t"/>'


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(min_value=0, max_value=10_000), max_size=30))
def test_framer_gives_the_same_events_whatever_the_chunking(cuts):
    big = hostile(uid="big").replace(b"<detail>", b"<detail><remarks>" + b"x" * LIMIT + b"</remarks>")
    stream = b"".join([hostile(uid="a"), big, hostile(uid="b"), b"<?xml version='1.0'?>", hostile(uid="c")])
    framer = EventFramer(LIMIT)
    events, skipped = _feed_all(framer, _chunks(stream, cuts))
    assert [cot.read_event(e).uid for e in events] == ["a", "b", "c"]
    assert skipped == [len(big) - big.index(b"<event")] and framer.skipped == 1


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.binary(max_size=300),
            st.sampled_from([b"<event", b"</event>", b"<event/>", b"/>", b">", b"<event ", b"</even"]),
        ),
        max_size=60,
    )
)
def test_framer_never_raises_and_stays_bounded_on_any_bytes(chunks):
    framer = EventFramer(256)
    for c in chunks:
        got = framer.feed(c)
        assert framer.buffered <= 256 + len(c)
        assert all(e.startswith(b"<event") and len(e) <= 256 for e in got.events)
        assert all(n > 256 for n in got.skipped_bytes)


def test_a_10_mb_event_costs_that_event_and_bounded_memory():
    hostile_10mb = hostile(uid="huge").replace(
        b"<detail>", b"<detail><remarks>" + b"A" * 10_000_000 + b"</remarks>"
    )
    stream = hostile_10mb + hostile(uid="fresh")
    framer = EventFramer(cot.MAX_EVENT_BYTES)
    chunk = 64 * 1024
    events, skipped, most = [], [], 0
    for i in range(0, len(stream), chunk):
        got = framer.feed(stream[i : i + chunk])
        events += got.events
        skipped += got.skipped_bytes
        most = max(most, framer.buffered)
    assert skipped == [len(hostile_10mb) - hostile_10mb.index(b"<event")] and [
        cot.read_event(e).uid for e in events
    ] == ["fresh"]
    assert most <= cot.MAX_EVENT_BYTES + chunk


def test_framer_refuses_a_silly_limit():
    with pytest.raises(ValueError, match="max_event_bytes"):
        EventFramer(10)


# -- TTL, tombstones -----------------------------------------------------------------------
def _state(**kw) -> BridgeState:
    return BridgeState(BridgeSettings(mission="m", origin=ORIGIN, rate_s=1.0, **kw))


def _puts(out) -> list[ZenohPut]:
    return [a for a in out.zenoh if isinstance(a, ZenohPut)]


def test_ttl_is_what_is_left_of_the_marker_life():
    s = _state()
    # sent 500 s ago with a 600 s life: a server's replay keeps only the 100 s left
    (put,) = _puts(s.on_cot(hostile(t=T0 - 500, ttl=600), T0))
    assert m.decode_threat(put.payload).ttl_s == pytest.approx(100.0)
    stale = cot.to_threat_change(cot.read_event(hostile(t=T0 - 700, ttl=600)), cot.ThreatDefaults(), T0)
    assert isinstance(stale, cot.ThreatRemoved)


def test_a_deleted_marker_is_not_revived_by_a_replay_until_its_stale_time():
    s = _state()
    marker = hostile(t=T0, ttl=600)
    (put,) = _puts(s.on_cot(marker, T0 + 1))
    assert s.on_cot(delete("ANDROID-7f.h1", t=T0 + 10), T0 + 10).zenoh == [ZenohDelete(put.key)]
    assert s.tombstones["ANDROID-7f.h1"] == Tombstone(after=T0 + 10, until=T0 + 600, source="TAK")
    # the server replays its copy on every (re)connection
    for now in (T0 + 20, T0 + 300, T0 + 599):
        assert s.on_cot(marker, now).zenoh == []
    assert s.refused_replays == 3
    # the same uid sent after the delete is a new marker
    (again,) = _puts(s.on_cot(hostile(t=T0 + 30, ttl=600), T0 + 31))
    assert again.key == put.key and "ANDROID-7f.h1" not in s.tombstones
    # tombstones go at the marker's stale time
    s.on_cot(delete("ANDROID-7f.h1", t=T0 + 40), T0 + 40)
    s.tick(T0 + 629)
    assert "ANDROID-7f.h1" in s.tombstones
    s.tick(T0 + 631)
    assert "ANDROID-7f.h1" not in s.tombstones


def test_a_delete_before_the_marker_and_a_marker_gone_stale_leave_tombstones():
    s = _state(tombstone_s=3600)
    s.on_cot(delete("early", t=T0), T0)
    assert s.tombstones["early"].until == pytest.approx(T0 + 3600)
    assert s.on_cot(hostile(uid="early", t=T0 - 5, ttl=600), T0 + 1).zenoh == []
    # a version stale on arrival removes the threat, and older versions stay away
    s.on_cot(hostile(uid="late", t=T0, ttl=600), T0)
    gone = s.on_cot(hostile(uid="late", t=T0 + 1, ttl=-1), T0 + 2)
    assert [type(a) for a in gone.zenoh] == [ZenohDelete]
    assert s.on_cot(hostile(uid="late", t=T0, ttl=600), T0 + 3).zenoh == []


def test_tombstones_are_bounded_and_restored(monkeypatch):
    from pfp_clients.tak import tombs as tombs_mod

    monkeypatch.setattr(tombs_mod, "MAX_TOMBSTONES", 100)
    s = _state()
    for i in range(tombs_mod.MAX_TOMBSTONES + 50):
        s.on_cot(delete(f"d{i}", t=T0 + i), T0 + i)
    assert len(s.tombstones) == tombs_mod.MAX_TOMBSTONES
    other = _state()
    other.restore_tombstones({"x": Tombstone(T0, T0 + 100), "old": Tombstone(T0 - 200, T0 - 100)}, T0)
    assert set(other.tombstones) == {"x"}
    assert other.on_cot(hostile(uid="x", t=T0 - 1), T0 + 1).zenoh == []


# -- pictures for links and devices that join --------------------------------------------------
def _with_a_route(s: BridgeState) -> None:
    s.on_state(keys.unit_state("m", "u1"), m.encode(m.UnitState(position=(0.0, 0.0))))
    d = m.Direction(unit="u1", status=m.DirectionStatus.EN_ROUTE, vector=(0.0, 1.0))
    s.on_direction(keys.unit_direction("m", "u1"), m.encode(d), T0)
    s.on_route("u1", [(0.0, 0.0), (0.0, 50.0), (10.0, 100.0)], "reached", 110.0, T0)
    threat = m.ThreatUpdate(position=(5.0, 5.0), sigma_range=5, sigma_lateral=5)
    s.on_threat(keys.threat("m", "t1"), m.encode(threat), T0)


def _types(out, link: str) -> list[str]:
    return sorted(ET.fromstring(d).get("type") for lk, d in out.to_link if lk == link)


def device(uid: str, t: float = T0) -> bytes:
    return (
        f'<event version="2.0" uid="{uid}" type="a-f-G-U-C" how="m-g" time="{cot.iso(t)}" '
        f'start="{cot.iso(t)}" stale="{cot.iso(t + 60)}"><point lat="58.41" lon="15.62" hae="0" '
        f'ce="9" le="9"/><detail><takv platform="ATAK"/><contact callsign="D"/>'
        f'<__group name="Cyan" role="Team Member"/></detail></event>'
    ).encode()


def test_a_link_that_comes_up_and_a_device_that_joins_get_every_route():
    s = _state(announce_min_s=1.0, device_forget_s=60.0)
    _with_a_route(s)
    s.tick(T0 + 0.5)
    s.on_link_up("tcp://tak", T0 + 1)
    assert _types(s.tick(T0 + 1), "tcp://tak") == ["a-f-G-E-V", "a-h-G", "b-m-r"]
    assert s.tick(T0 + 1.1).to_link == []
    s.on_cot(device("ANDROID-new"), T0 + 1.5, "tcp://tak")  # within announce_min_s of the last picture
    assert s.tick(T0 + 1.6).to_link == []
    assert _types(s.tick(T0 + 2.0), "tcp://tak") == ["a-f-G-E-V", "a-h-G", "b-m-r"]
    s.on_cot(device("ANDROID-new"), T0 + 5, "tcp://tak")  # heard again: not new
    assert s.tick(T0 + 6).to_link == []
    s.on_cot(device("ANDROID-new"), T0 + 70, "tcp://tak")  # silent past device_forget_s: joined again
    assert _types(s.tick(T0 + 70), "tcp://tak") == ["a-f-G-E-V", "a-h-G", "b-m-r"]
    assert s.on_cot(device("pfp.unit.m.u1"), T0 + 80, "tcp://tak").to_link == []  # our own echo is no device
    assert s.tick(T0 + 80).to_link == []


def test_points_carry_the_origin_altitude():
    s = _state()
    _with_a_route(s)
    s.on_link_up("l", T0)
    for _link, data in s.tick(T0).to_link:
        ev = ET.fromstring(data)
        assert float(ev.find("point").get("hae")) == 123.5
        for lk in ev.findall("detail/link"):
            assert float(lk.get("point").split(",")[2]) == 123.5
    s.on_threat(keys.threat("m", "t1"), None, T0 + 5)


# -- tombstones on disk ---------------------------------------------------------------------
def test_tombstones_survive_in_a_file_and_a_damaged_file_is_set_aside(tmp_path):
    from pfp_clients.tak import tombfile

    path = tmp_path / "m" / tombfile.FILE_NAME
    assert tombfile.load(path, T0) == tombfile.Loaded()  # none yet
    kept = {"a": Tombstone(T0, T0 + 100), "gone": Tombstone(T0 - 50, T0 - 1)}
    assert tombfile.save(path, kept) is None
    assert tombfile.load(path, T0).tombstones == {"a": Tombstone(T0, T0 + 100)}
    for junk in (b"\x00\xff garbage", b'{"a": [1, "x"]}', b'{"a": [1, NaN]}', b"[]"):
        path.write_bytes(junk)
        loaded = tombfile.load(path, T0)
        assert loaded.tombstones == {} and "unreadable" in (loaded.note or ""), junk
        assert not path.exists() and (path.parent / f"{path.name}.corrupt-{int(T0)}").exists()
    (tmp_path / "file").write_text("x")
    note = tombfile.save(tmp_path / "file" / tombfile.FILE_NAME, kept)  # a file where the folder goes
    assert note is not None and "cannot save tombstones" in note


def test_the_keeper_writes_on_change_and_says_a_failure_once(tmp_path):
    from pfp_clients.tak import tombfile

    path = tmp_path / tombfile.FILE_NAME
    notes: list[str] = []
    s = _state()
    keeper = tombfile.Keeper(path, notes.append)
    assert keeper.restore(s, T0) == 0
    keeper.keep(s)
    assert not path.exists()  # nothing changed, nothing written
    s.on_cot(hostile(t=T0, ttl=600), T0)
    s.on_cot(delete("ANDROID-7f.h1", t=T0 + 1), T0 + 1)
    keeper.keep(s)
    again = _state()
    assert tombfile.Keeper(path, notes.append).restore(again, T0 + 2) == 1
    assert again.on_cot(hostile(t=T0, ttl=600), T0 + 3).zenoh == []  # the restart's replay
    blocked = tombfile.Keeper(tmp_path / "f" / "x.json", notes.append)
    (tmp_path / "f").write_text("a file where the folder goes")
    for i in range(3):
        s.on_cot(delete(f"more{i}", t=T0 + 5), T0 + 5)
        blocked.keep(s)
    assert len(notes) == 1 and "cannot save tombstones" in notes[0]


def test_pfp_state_clear_knows_the_tombstone_file_by_the_bridges_own_name():
    """``pfp state clear`` removes the bridge's tombstones with the mission's state (pfp_service names the file)."""
    from pfp_clients.tak.tombfile import FILE_NAME

    from pfp_service.node.statefile import COMPANION_NAMES

    assert FILE_NAME in COMPANION_NAMES
