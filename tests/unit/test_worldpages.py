"""The world queryable in pages: bounded replies, cursors, hostile parameters, and a joiner fetching all."""

from __future__ import annotations

import pytest

from pfp_service.core import PlannerParams
from pfp_service.errors import InputError
from pfp_service.node.worldpages import answer_world, fetch_world, whole_world
from pfp_service.wire import (
    MAX_PAYLOAD_BYTES,
    Goal,
    ThreatUpdate,
    UnitState,
    WorldQuery,
    decode_error_reply,
    decode_world_query,
    decode_world_snapshot,
    encode,
    keys,
)
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.world import GoalSet, StateReported, TeamPut, ThreatPut, World, WorldSettings

pytestmark = pytest.mark.unit

M = "pages"
T = dict(facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7, skew=2.0)


def _settings(pid: str) -> WorldSettings:
    # plain descent, no look-ahead points: these worlds are about what is held, not how it is planned
    planner = PlannerParams(intensity="density", delta=0.08, escape="none")
    return WorldSettings(planner=planner, mission=M, planner_id=pid, lookahead=0)


def _world(pid: str, units: int, threats: int) -> World:
    """``units`` units on their goals (each mission fixed) and ``threats`` threats far from them."""
    w = World(_settings(pid))
    ids = [f"u{i:05d}" for i in range(units)]
    far = [ThreatPut(f"t{j:04d}", ThreatUpdate(position=(5000.0 + 10 * j, 6.0), **T)) for j in range(threats)]
    w.apply([GoalSet(u, Goal(position=(10.0, 10.0 + i % 7))) for i, u in enumerate(ids)], 0.0)
    w.apply([StateReported(u, UnitState(position=(0.001 * i, 0.0))) for i, u in enumerate(ids)], 0.0)
    # the threats last: each unit's first look-ahead then sums an empty field, not 1,200 far threats (5x cheaper)
    w.apply(far, 0.0)
    return w


UNITS, THREATS = 3000, 1200  # past one page of each (MAX_PAYLOAD_BYTES), in both the units and the threats


@pytest.fixture(scope="module")
def big() -> tuple[World, World]:
    """Two planners' worlds of ``UNITS`` and ``THREATS``, built once for the module: each unit's report
    runs its look-ahead as it is taken in, the dearest part of these tests, and paging only reads them."""
    return _world("p1", UNITS, THREATS), _world("p2", UNITS, THREATS)


class _Peers:
    """What ``session.get`` would return, from in-process worlds; ``silent`` peers stop answering pages."""

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
            w = self.worlds[pid]
            page = w.snapshot(
                1.0,
                q.units_limit,
                q.units_from,
                q.threats_from,
                threats_limit=q.threats_limit,
                zones_from=q.zones_from,
                zones_limit=q.zones_limit,
                writes_from=q.writes_from,
                writes_limit=q.writes_limit,
            )
            out.append(encode(page))
        return out


def test_a_page_always_decodes_and_cursors_list_every_id_once(big):
    w = big[0]
    units: list[str] = []
    threats: list[str] = []
    q = WorldQuery()
    for _ in range(50):
        data = encode(
            w.snapshot(1.0, q.units_limit, q.units_from, q.threats_from, threats_limit=q.threats_limit)
        )
        assert len(data) <= MAX_PAYLOAD_BYTES
        page = decode_world_snapshot(data)
        assert page.units_total == UNITS and page.threats_total == THREATS
        assert page.units or page.threats  # every page makes progress
        units += [u.id for u in page.units]
        threats += [t.id for t in page.threats]
        if page.next_unit is None and page.next_threat is None:
            break
        q = WorldQuery(
            units_from=page.next_unit,
            threats_from=page.next_threat,
            units_limit=0 if page.next_unit is None else 1000,
            threats_limit=0 if page.next_threat is None else 1000,
        )
    assert units == sorted(set(units)) and len(units) == UNITS
    assert threats == sorted(set(threats)) and len(threats) == THREATS


def test_small_worlds_are_one_page_and_limits_are_kept():
    w = _world("p1", 5, 3)
    page = w.snapshot(1.0)
    assert (len(page.units), len(page.threats), page.next_unit, page.next_threat) == (5, 3, None, None)
    page = w.snapshot(1.0, 2, units_from="u00001", threats_limit=0)
    assert [u.id for u in page.units] == ["u00001", "u00002"] and page.next_unit == "u00003"
    assert page.threats == [] and page.next_threat is None  # left out: no cursor


@pytest.mark.parametrize(
    ("params", "path"),
    [
        ("units_limit=-1", "$.units_limit"),
        ("threats_limit=1001", "$.threats_limit"),
        ("units_limit=ten", "$.units_limit"),
        ("units_from=a/b", "$.units_from"),
        ("units_from=" + "x" * 65, "$.units_from"),
        ("units_from=", "$.units_from"),
        ("offset=5", "$.offset"),
        ("units_from=a;units_from=b", "$.units_from"),
        ("justaname", "$"),
        ("units_from=a;" * 200, "$"),
        ("\u00e9=1", "$"),
    ],
)
def test_bad_parameters_are_refused_with_their_path(params, path):
    with pytest.raises(InputError) as err:
        decode_world_query(params)
    assert err.value.path == path


class _Query:
    def __init__(self, parameters: str) -> None:
        self.parameters = parameters
        self.replies: list[tuple[str, bytes]] = []
        self.errors: list[bytes] = []

    def reply(self, key: str, payload: bytes, encoding: object = None) -> None:
        self.replies.append((key, payload))

    def reply_err(self, payload: bytes, encoding: object = None) -> None:
        self.errors.append(payload)


def test_the_queryable_answers_a_page_or_a_structured_error():
    w = _world("p1", 30, 2)
    q = _Query("units_from=u00010;units_limit=5;threats_limit=0")
    answer_world(q, w, 1.0, M, "p1")
    ((key, payload),) = q.replies
    page = decode_world_snapshot(payload)
    assert key == keys.world(M, "p1") and page.units[0].id == "u00010"
    assert len(page.units) == 5 and page.next_unit == "u00015" and not q.errors
    bad = _Query("units_limit=99999")
    answer_world(bad, w, 1.0, M, "p1")
    (err,) = bad.errors
    assert not bad.replies and decode_error_reply(err).field == "$.units_limit"


def test_a_joiner_learns_every_unit_and_threat_across_pages(big):
    peers = _Peers(list(big))
    joined = fetch_world(peers, M, "p9")
    assert joined.complete and joined.peers == 2
    assert joined.pages > 3  # a first page from each, then the rest from one peer
    assert sum("p2/world?" in a for a in peers.asked) == 0 or sum("p1/world?" in a for a in peers.asked) == 0
    me = World(_settings("p9"))
    me.apply(joined.inputs, 2.0)
    assert me.counts()["units"] == UNITS and me.counts()["threats"] == THREATS
    snap = me.snapshot(2.0, threats_limit=0)
    assert all(u.goal is not None and u.goal[0] == 10.0 for u in snap.units)
    assert all(u.mission is not None and u.mission.origin[1] == 0.0 for u in snap.units)  # x0 kept


def test_a_joiner_goes_on_from_the_same_cursor_when_its_peer_stops_answering(big):
    peers = _Peers(list(big))
    peers.silent.add("p1")  # the fullest (tie: first by id) answers only the first ask
    joined = fetch_world(peers, M, "p9")
    assert joined.complete and any("p2/world?" in a for a in peers.asked)
    assert len({i.unit for i in joined.inputs if hasattr(i, "unit")}) == UNITS


def test_the_fetch_is_bounded_and_says_so(big):
    peers = _Peers([big[0]])
    joined = fetch_world(peers, M, "p9", max_pages=2)
    assert not joined.complete and joined.pages == 2
    t = iter([0.0] + [100.0] * 10)  # past the deadline after the first ask
    joined = fetch_world(peers, M, "p9", clock=lambda: next(t), deadline_s=10.0)
    assert not joined.complete and joined.pages == 1
    peers.silent.add("p1")
    joined = fetch_world(peers, M, "p9")
    assert not joined.complete and joined.pages == 1
    assert fetch_world(_Peers([]), M, "p9").complete  # nobody to join: nothing missing


def test_status_gets_one_planners_whole_world_merged(big):
    peers = _Peers([big[0]])
    (first,) = [decode_world_snapshot(b) for b in peers(keys.worlds(M), 1.0)]
    assert first.next_unit is not None or first.next_threat is not None
    merged, complete = whole_world(peers, M, first)
    assert complete and len(merged.units) == UNITS and len(merged.threats) == THREATS
    assert merged.next_unit is None and merged.next_threat is None
    cut, complete = whole_world(peers, M, first, max_pages=2)
    assert not complete and len(cut.units) < UNITS and (cut.next_unit or cut.next_threat)


def test_the_kinds_listed_by_kind_page_by_cursor_and_a_joiner_learns_every_one():
    w = World(_settings("p1"))
    w.apply([TeamPut(f"t{i}", TeamUpdate(members=[f"a{i}", f"b{i}"])) for i in range(5)], 0.0)
    first = w.snapshot(1.0, writes_limit=2)
    assert [x.id for x in first.writes] == ["t0", "t1"] and first.next_write == "team.t2"
    assert first.writes_total == 5 and len(first.teams) == 5  # the teams for people, whole, as before
    assert (
        decode_world_query(WorldQuery(writes_from="team.t2").selector_parameters()).writes_from == "team.t2"
    )
    joined = fetch_world(_Peers([w]), M, "p2")
    assert joined.complete and joined.writes == 5
    assert [i for i in joined.inputs if isinstance(i, TeamPut)] == [
        TeamPut(f"t{i}", w.teams.teams[f"t{i}"]) for i in range(5)
    ]
    with pytest.raises(InputError):  # a cursor is a kind's name and an id
        decode_world_query("writes_from=t2")
