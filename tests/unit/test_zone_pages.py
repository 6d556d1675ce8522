"""Keep-out zones page like threats: a world with more zones than one reply holds reaches a joiner whole.

A zone may carry up to 4,096 vertices (90 to 165 KB of JSON), so a handful of
detailed zones already overflow one 192 KB page; before zone paging a joining
planner took only the zones of the first page.
"""

from __future__ import annotations

import math

import pytest

from pfp_service.core import PlannerParams
from pfp_service.errors import InputError
from pfp_service.node.worldpages import fetch_world, whole_world
from pfp_service.wire import (
    MAX_PAYLOAD_BYTES,
    Goal,
    ThreatUpdate,
    UnitState,
    WorldQuery,
    decode_world_query,
    decode_world_snapshot,
    encode,
    keys,
)
from pfp_service.wire.messages import SNAPSHOT_PAGE_BYTES, ZoneCircle, ZoneUpdate
from pfp_service.world.events import ZonePut, ZoneRemoved
from pfp_service.world.world import GoalSet, StateReported, ThreatPut, World, WorldSettings

pytestmark = pytest.mark.unit

M = "zpages"
T = dict(facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7, skew=2.0)


def _settings(pid: str) -> WorldSettings:
    planner = PlannerParams(intensity="density", delta=0.08, escape="none")
    return WorldSettings(planner=planner, mission=M, planner_id=pid, lookahead=0)


def _detailed(cx: float, cy: float, vertices: int = 3000, r: float = 40.0) -> ZoneUpdate:
    """A closed many-sided polygon round (cx, cy): one big zone on the wire (~100 KB at 3,000 vertices)."""
    ring = [
        (
            round(cx + r * math.cos(2 * math.pi * k / vertices), 6),
            round(cy + r * math.sin(2 * math.pi * k / vertices), 6),
        )
        for k in range(vertices)
    ]
    return ZoneUpdate(polygon=[[*ring, ring[0]]])


def _zone_world(pid: str, zones: int, units: int = 0, threats: int = 0, ttl: float | None = None) -> World:
    """``zones`` detailed zones far apart (some circles), plus units and threats away from them."""
    w = World(_settings(pid))
    puts = []
    for j in range(zones):
        cx, cy = 1000.0 + 200.0 * j, 2000.0
        if j % 4 == 3:
            z = ZoneUpdate(circle=ZoneCircle(centre=(cx, cy), radius_m=30.0), ttl_s=ttl)
        else:
            z = _detailed(cx, cy)
            z = ZoneUpdate(polygon=z.polygon, ttl_s=ttl)
        puts.append(ZonePut(f"z{j:03d}", z))
    w.apply(puts, 0.0)
    far = [ThreatPut(f"t{j:04d}", ThreatUpdate(position=(5000.0 + 10 * j, 6.0), **T)) for j in range(threats)]
    w.apply(far, 0.0)
    ids = [f"u{i:05d}" for i in range(units)]
    w.apply([GoalSet(u, Goal(position=(10.0, 10.0 + i % 7))) for i, u in enumerate(ids)], 0.0)
    w.apply([StateReported(u, UnitState(position=(0.001 * i, 0.0))) for i, u in enumerate(ids)], 0.0)
    assert w.counts()["zones"] == zones
    return w


class _Peers:
    """``session.get`` over in-process worlds, as the world queryable answers it; ``silent`` ones stop paging."""

    def __init__(self, worlds: list[World]) -> None:
        self.worlds = {w.settings.planner_id: w for w in worlds}
        self.silent: set[str] = set()
        self.asked: list[str] = []

    def __call__(self, selector: str, timeout_s: float) -> list[bytes]:
        self.asked.append(selector)
        key, _, params = selector.partition("?")
        q = decode_world_query(params)
        who = list(self.worlds) if key == keys.worlds(M) else [keys.parse(key).id]
        out = []
        for pid in who:
            if pid in self.silent and params:
                continue
            page = self.worlds[pid].snapshot(
                1.0,
                q.units_limit,
                q.units_from,
                q.threats_from,
                threats_limit=q.threats_limit,
                zones_from=q.zones_from,
                zones_limit=q.zones_limit,
            )
            data = encode(page)
            assert len(data) <= MAX_PAYLOAD_BYTES
            out.append(data)
        return out


def test_zones_past_one_page_are_paged_by_cursor_each_listed_once():
    w = _zone_world("p1", 16, units=40, threats=30)
    zones: list[str] = []
    threats: list[str] = []
    units: list[str] = []
    q = WorldQuery()
    pages = 0
    while True:
        data = encode(
            w.snapshot(
                1.0,
                q.units_limit,
                q.units_from,
                q.threats_from,
                threats_limit=q.threats_limit,
                zones_from=q.zones_from,
                zones_limit=q.zones_limit,
            )
        )
        assert len(data) <= SNAPSHOT_PAGE_BYTES + 1024  # the items stop short of it; the envelope is small
        page = decode_world_snapshot(data)
        pages += 1
        assert page.zones_total == 16 and page.threats_total == 30 and page.units_total == 40
        assert page.zones or page.threats or page.units  # every page makes progress
        zones += [z.id for z in page.zones]
        threats += [t.id for t in page.threats]
        units += [u.id for u in page.units]
        if page.next_zone is None and page.next_threat is None and page.next_unit is None:
            break
        assert pages < 50
        q = WorldQuery(
            zones_from=page.next_zone,
            threats_from=page.next_threat,
            units_from=page.next_unit,
            zones_limit=0 if page.next_zone is None else 1000,
            threats_limit=0 if page.next_threat is None else 1000,
            units_limit=0 if page.next_unit is None else 1000,
        )
    assert pages >= 4  # 12 polygons of ~100 KB take two to a 192 KB page
    assert zones == sorted(set(zones)) and len(zones) == 16
    assert threats == sorted(set(threats)) and len(threats) == 30
    assert units == sorted(set(units)) and len(units) == 40


def test_a_zone_cursor_and_limit_are_kept_and_zero_leaves_zones_out():
    w = _zone_world("p1", 8)
    page = w.snapshot(1.0, zones_from="z003", zones_limit=2)
    assert [z.id for z in page.zones] == ["z003", "z004"] and page.next_zone == "z005"
    page = w.snapshot(1.0, zones_from="z0035")  # a cursor between ids starts at the next one
    assert page.zones[0].id == "z004"
    page = w.snapshot(1.0, threats_from="t", zones_limit=0)
    assert page.zones == [] and page.next_zone is None and page.zones_total == 8
    tiny = w.snapshot(1.0, max_bytes=10)  # room for nothing: one zone anyway, so paging ends
    assert [z.id for z in tiny.zones] == ["z000"] and tiny.next_zone == "z001"
    assert tiny.threats == [] and tiny.units == []


def test_zones_put_or_removed_between_pages_shift_nothing():
    w = _zone_world("p1", 10)
    first = w.snapshot(1.0, zones_limit=4, max_bytes=10**9)
    assert [z.id for z in first.zones] == ["z000", "z001", "z002", "z003"] and first.next_zone == "z004"
    w.apply([ZoneRemoved("z001"), ZoneRemoved("z006"), ZonePut("a", _detailed(-500.0, 0.0, 8))], 1.0)
    rest = w.snapshot(1.0, zones_from=first.next_zone, max_bytes=10**9)
    assert [z.id for z in rest.zones] == ["z004", "z005", "z007", "z008", "z009"]
    assert rest.next_zone is None and rest.zones_total == 9


@pytest.mark.parametrize(
    ("params", "path"),
    [
        ("zones_limit=-1", "$.zones_limit"),
        ("zones_limit=1001", "$.zones_limit"),
        ("zones_from=a/b", "$.zones_from"),
        ("zones_from=", "$.zones_from"),
        ("zones_from=a;zones_from=b", "$.zones_from"),
    ],
)
def test_bad_zone_parameters_are_refused_with_their_path(params, path):
    with pytest.raises(InputError) as err:
        decode_world_query(params)
    assert err.value.path == path


def test_zone_parameters_round_trip_through_the_selector():
    q = WorldQuery(zones_from="z007", zones_limit=0, threats_limit=0)
    assert decode_world_query(q.selector_parameters()) == q
    assert "zones_from=z007" in q.selector_parameters()


def test_a_joiner_takes_every_zone_past_the_first_page_with_the_time_left():
    peers = _Peers([_zone_world("p1", 14, units=20, threats=5, ttl=60.0), _zone_world("p2", 14, ttl=60.0)])
    first = decode_world_snapshot(peers(keys.worlds(M), 1.0)[0])
    assert len(first.zones) < first.zones_total == 14 and first.next_zone is not None  # it takes paging
    joined = fetch_world(peers, M, "p9")
    assert joined.complete and joined.peers == 2
    assert any("zones_from=" in a for a in peers.asked)
    me = World(_settings("p9"))
    me.apply(joined.inputs, 10.0)
    assert me.counts()["zones"] == 14 and me.counts()["threats"] == 5 and me.counts()["units"] == 20
    assert me.field.zones.ids == tuple(f"z{j:03d}" for j in range(14))
    mine = me.snapshot(10.0, limit=1000, max_bytes=10**9)
    assert len(mine.zones) == 14
    assert all(z.ttl_s == pytest.approx(59.0) for z in mine.zones)  # 60 s put at 0, listed at 1
    original = {z.id: z.zone.polygon for z in peers.worlds["p1"].snapshot(1.0, max_bytes=10**9).zones}
    assert {z.id: z.zone.polygon for z in mine.zones} == original  # every vertex came


def test_a_joiner_goes_on_with_the_zones_from_the_same_cursor_when_its_peer_stops():
    peers = _Peers([_zone_world("p1", 12), _zone_world("p2", 12)])
    peers.silent.add("p1")  # the fullest (tie: first by id) answers only the first ask
    joined = fetch_world(peers, M, "p9")
    assert joined.complete and any("p2/world?" in a and "zones_from=" in a for a in peers.asked)
    assert {i.zone for i in joined.inputs if isinstance(i, ZonePut)} == {f"z{j:03d}" for j in range(12)}


def test_a_fetch_cut_short_among_the_zones_says_it_is_incomplete():
    peers = _Peers([_zone_world("p1", 12)])
    joined = fetch_world(peers, M, "p9", max_pages=1)
    assert not joined.complete and 0 < joined.zones < 12


def test_status_gets_every_zone_of_a_planner_merged():
    peers = _Peers([_zone_world("p1", 13, units=3, threats=2)])
    (first,) = [decode_world_snapshot(b) for b in peers(keys.worlds(M), 1.0)]
    assert first.next_zone is not None
    merged, complete = whole_world(peers, M, first)
    assert complete and merged.next_zone is None
    assert [z.id for z in merged.zones] == [f"z{j:03d}" for j in range(13)]
    assert len(merged.threats) == 2 and len(merged.units) == 3
    cut, complete = whole_world(peers, M, first, max_pages=1)
    assert not complete and cut.next_zone == first.next_zone and len(cut.zones) == len(first.zones)
