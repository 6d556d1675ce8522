"""Hostile TAK input (issue 35): a flood of deletes cannot push out older tombstones, the tombstone
file stays within what is read back, and a DTD is refused in any encoding (UTF-16 included)."""

from __future__ import annotations

import time

import pytest
from pfp_clients.tak import cot, tombfile
from pfp_clients.tak.outputs import ZenohPut
from pfp_clients.tak.state import BridgeSettings, BridgeState
from pfp_clients.tak.tombs import MAX_TOMBSTONES, MAX_TOMBSTONES_PER_SOURCE

from pfp_service.geo import Origin
from tests.unit.test_tak_cot import T0, hostile

pytestmark = pytest.mark.unit

ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=0.0)
TEN_YEARS_S = 10 * 365 * 86_400


def _state() -> BridgeState:
    return BridgeState(BridgeSettings(mission="m", origin=ORIGIN, rate_s=1.0))


def _delete(target: str, t: float, stale: float, uid: str = "del") -> bytes:
    return (
        f'<event version="2.0" uid="{uid}" type="t-x-d-d" how="h-g-i-g-o" time="{cot.iso(t)}" '
        f'start="{cot.iso(t)}" stale="{cot.iso(stale)}"><point lat="0" lon="0" hae="0" ce="1" le="1"/>'
        f'<detail><link uid="{target}" relation="none" type="a-h-G"/><__forcedelete/></detail></event>'
    ).encode()


def _puts(out) -> list[ZenohPut]:
    return [a for a in out.zenoh if isinstance(a, ZenohPut)]


@pytest.mark.parametrize("flood_source", ["tak.example:8089", "udp:203.0.113.9:4242"])
def test_a_flood_of_far_future_deletes_does_not_revive_a_deleted_marker(flood_source):
    s = _state()
    legit = [f"ANDROID-{i:03d}" for i in range(100)]
    for uid in legit:  # markers the server has, then deleted by the operators
        assert _puts(s.on_cot(hostile(uid=uid, t=T0, ttl=600), T0, "tak.example:8089"))
        s.on_cot(_delete(uid, T0 + 1, T0 + 21), T0 + 1, "tak.example:8089")
    t0 = time.perf_counter()
    for i in range(10_001):
        s.on_cot(_delete(f"flood-{i}", T0 + 2, T0 + TEN_YEARS_S), T0 + 2, flood_source)
    took = time.perf_counter() - t0
    assert all(uid in s.tombstones for uid in legit), f"{sum(u in s.tombstones for u in legit)} of 100 kept"
    assert len(s.tombstones) <= MAX_TOMBSTONES and s.tombs.refused > 0
    for uid in legit:  # the server replays every marker on the next connection
        assert _puts(s.on_cot(hostile(uid=uid, t=T0, ttl=600), T0 + 5, "tak.example:8089")) == [], uid
    print(
        f"10,001 deletes from {flood_source} in {took:.2f} s; {len(s.tombstones)} tombstones; 100 of 100 kept"
    )


def test_sources_share_a_full_bridge_fairly():
    s = _state()
    for k in range(5):
        for i in range(MAX_TOMBSTONES_PER_SOURCE + 10):
            s.on_cot(_delete(f"s{k}-{i}", T0, T0 + TEN_YEARS_S), T0, f"source-{k}")
    counts = {k: sum(t.source == f"source-{k}" for t in s.tombstones.values()) for k in range(5)}
    assert len(s.tombstones) == MAX_TOMBSTONES and max(counts.values()) - min(counts.values()) <= 1, counts
    assert all(f"s0-{i}" in s.tombstones for i in range(1000))  # the first ones stay


def test_the_tombstone_file_stays_within_what_is_read_back(tmp_path):
    s = _state()
    for k in range(4):
        for i in range(MAX_TOMBSTONES_PER_SOURCE):
            target = f"{k}-{i}-".ljust(cot.MAX_UID_CHARS, '"')  # the longest uid, escaped in JSON
            s.on_cot(
                _delete(target.replace('"', "&quot;"), T0, T0 + TEN_YEARS_S), T0, f"link-{k}-" + "x" * 300
            )
    assert len(s.tombstones) == MAX_TOMBSTONES
    path = tmp_path / tombfile.FILE_NAME
    assert tombfile.save(path, s.tombstones) is None
    size = path.stat().st_size
    loaded = tombfile.load(path, T0)
    assert loaded.note is None and len(loaded.tombstones) == MAX_TOMBSTONES, loaded.note
    print(f"a full tombstone file of the longest uids: {size:,} bytes, read back whole")
    # a 60 KB uid is refused with its event: it never reaches the file
    big = s.on_cot(_delete("u" * 60_000, T0, T0 + TEN_YEARS_S), T0, "tak")
    assert big.zenoh == [] and s.dropped == 1 and ("u" * 60_000) not in s.tombstones


_ENTITY_EVENT = (
    '<?xml version="1.0" encoding="UTF-16"?>'
    '<!DOCTYPE event [<!ENTITY u "pwned">]>'
    '<event version="2.0" uid="&u;" type="a-h-G-U-C" how="h-g-i-g-o" time="{t}" start="{t}" stale="{s}">'
    '<point lat="58.415" lon="15.63" hae="0" ce="1" le="1"/><detail/></event>'
)
_LAUGHS = (
    '<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">'
    + "".join(
        f'<!ENTITY lol{i} "{("&lol" + str(i - 1) + ";") * 10 if i > 1 else "&lol;" * 10}">'
        for i in range(1, 10)
    )
    + ']><event uid="&lol9;" type="a-h-G"><point lat="0" lon="0"/></event>'
)


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-8"])
def test_a_dtd_is_refused_in_any_encoding(encoding):
    text = _ENTITY_EVENT.format(t=cot.iso(T0), s=cot.iso(T0 + 600))
    if encoding == "utf-8":
        text = text.replace('encoding="UTF-16"', 'encoding="UTF-8"')
    data = text.encode(encoding) if encoding != "utf-16-be" else b"\xfe\xff" + text.encode(encoding)
    with pytest.raises(cot.CotError, match="DTDs and entities are not accepted"):
        cot.read_event(data)
    s = _state()
    out = s.on_cot(data, T0, "udp:203.0.113.9:4242")
    assert out.zenoh == [] and s.dropped == 1


def test_billion_laughs_and_an_undeclared_entity_are_refused_at_once():
    t0 = time.perf_counter()
    for data in (_LAUGHS.encode(), _LAUGHS.encode("utf-16")):
        with pytest.raises(cot.CotError, match="DTDs and entities"):
            cot.read_event(data)
    assert time.perf_counter() - t0 < 0.1
    with pytest.raises(cot.CotError, match="not XML"):
        cot.read_event(hostile().replace(b'uid="ANDROID-7f.h1"', b'uid="&u;"'))


def test_a_plain_utf16_event_still_reads():
    ev = cot.read_event(hostile().decode().replace('<?xml version="1.0"?>', "").encode("utf-16"))
    assert ev.uid == "ANDROID-7f.h1"
