"""The one table of input kinds (world/kinds.py): every key the world takes input on has one entry,
and what is derived from it (subscriptions, the generic write handler, ACL grants, store tables,
log lines, blame, the docs' key table) covers each entry."""

from __future__ import annotations

import re
import threading
import typing
from pathlib import Path

import pytest

from pfp_service.errors import InputError
from pfp_service.node import access
from pfp_service.node.config import ServeConfig
from pfp_service.node.store import TABLES, Store
from pfp_service.node.writes import Writes
from pfp_service.wire import RestoredEvent, decode_event, decode_world_query, encode, keys
from pfp_service.wire.contract import examples
from pfp_service.wire.schema import LIVELINESS, MESSAGES
from pfp_service.world import kinds
from pfp_service.world.events import Input, InputRejected, MissionRestored, Tick, WorldSettings, Written
from pfp_service.world.kinds import KINDS, STORED, WRITES

pytestmark = pytest.mark.unit

M = "m1"
ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "wire.md"


def _example(kind: kinds.Kind):
    assert kind.schema is not None
    return examples()[kind.schema][0][1]


def test_every_key_the_world_takes_input_on_has_exactly_one_entry():
    # from the wire contract, not from the table: what is put to a planner, and the liveliness tokens
    inputs = {s.key for s in MESSAGES if s.receiver == "planner" and s.op == "put"} | set(LIVELINESS)
    named = [k.key for k in KINDS]
    assert sorted(named) == sorted(inputs)
    assert len(set(named)) == len(named)
    assert len({k.name for k in KINDS}) == len(KINDS)
    # an input class belongs to one kind; a write kind has its put and its remove
    assert sum(len(k.inputs) for k in KINDS) == len(kinds.BY_INPUT)
    for k in WRITES:
        assert len(k.inputs) >= 2 and k.decode is not None and k.log_put and k.log_remove


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_its_schema_is_the_contract_message_of_its_key_and_its_decoder_reads_it(kind):
    if kind.schema is None:
        assert kind.key in LIVELINESS
        return
    (spec,) = [s for s in MESSAGES if s.name == kind.schema]
    assert spec.key is kind.key and spec.receiver == "planner"
    msg = _example(kind)
    assert kind.decode is not None and kind.decode(encode(msg), None, None) == msg


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_each_kind_has_a_mode_the_node_wires_and_a_wildcard_of_its_own_key(kind):
    # node._wire matches on the mode with assert_never, so mypy refuses a mode it does not wire;
    # tests/proc/test_kinds_wiring.py checks the subscriptions a real node declares
    assert kind.mode in typing.get_args(kinds.Mode)
    key_expr = kind.wildcard(M)
    assert key_expr == keys.TEMPLATES[kind.key].format(mission=M, id="*")
    assert keys.parse(key_expr.replace("*", "x1")) == keys.Key(kind.key, M, "x1")


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_a_write_kinds_inputs_and_only_those_are_written(kind):
    # Input names events.Written once: a new kind's put and remove derive from it, wherever declared
    written = [issubclass(cls, Written) for cls in kind.inputs]
    if kind.mode == "write":
        assert written[:2] == [True, True] and not any(written[2:])
    else:
        assert not any(written)
    assert all(cls in typing.get_args(Input) or issubclass(cls, Written) for cls in kind.inputs)


@pytest.mark.parametrize("kind", WRITES, ids=lambda k: k.name)
def test_the_one_write_handler_makes_each_kinds_put_remove_and_refusals(kind):
    writes = Writes(ServeConfig(mission=M), "zid", threading.Lock(), lambda: None, lambda: None)
    make = writes._maker(kind, M)
    key = kind.key_of(M, "x1")
    msg = _example(kind)
    put = make(key, False, encode(msg))
    assert type(put) is kind.put and kinds.ident(put) == "x1" and kinds.message(put) == msg
    gone = make(key, True, b"")
    assert type(gone) is kind.remove and kinds.ident(gone) == "x1"
    bad = make(key, False, b"{")  # the key parsed: refused on its kind's window
    assert isinstance(bad, InputRejected) and bad.key == key and bad.kind is kind.key
    odd = key.replace("x1", "x$1")  # the key itself is refused: outside the layout, no kind
    refused = make(odd, False, encode(msg))
    assert isinstance(refused, InputRejected) and refused.kind is None and refused.error.path == "key"


@pytest.mark.parametrize("role", sorted({r for k in KINDS for r in k.writers}))
def test_every_writer_role_is_a_role_of_the_acl(role):
    assert role in access.ROLES


def _allows(grants, flow: str, message: str, key: str) -> bool:
    return any(g.flow == flow and message in g.messages and key in g.key_exprs for g in grants)


@pytest.mark.parametrize("kind", WRITES, ids=lambda k: k.name)
def test_the_acl_grants_each_write_kind_to_its_writers_and_the_planner_only(kind):
    team = access.Mission(M, ("p1",), ("u1",))
    roles = {name: (name,) for name in access.ROLES}
    by_name = {p.name: p.grants for p in access.principals_for(team, roles)}
    wild = kind.wildcard(M)
    for role in access.ROLES:
        may = _allows(by_name[role], "ingress", "put", wild) and _allows(
            by_name[role], "ingress", "delete", wild
        )
        assert may == (role in kind.writers), role
    planner = by_name["planner"]
    for message in ("declare_subscriber", "declare_queryable"):
        assert _allows(planner, "ingress", message, wild)
    own = kind.key_of(M, "u1")
    assert _allows(by_name["unit-u1"], "ingress", "put", own) == kind.own_unit
    bare = access.principals_for(access.Mission(M, ("p1",), ("u1",), own_goal=False), {})
    assert not _allows(bare[0].grants, "ingress", "put", own)


@pytest.mark.parametrize("kind", [k for k in KINDS if k.mode != "write"], ids=lambda k: k.name)
def test_the_acl_lets_the_writers_of_each_other_kind_write_it(kind):
    team = access.Mission(M, ("p1",), ("u1",))
    by_name = {p.name: p.grants for p in access.principals_for(team, {"p1": ("planner",)})}
    how = ("liveliness_token",) if kind.mode in ("token", "peers") else ("put",)
    for role in kind.writers:
        assert role == "planner"  # the only mission-wide writer of these today
        key = kind.key_of(M, "p1")
        assert any(
            _allows(by_name["p1"], "ingress", m, key)
            or _allows(by_name["p1"], "ingress", m, kind.wildcard(M))
            for m in how
        )
    if kind.own_unit:
        assert any(_allows(by_name["unit-u1"], "ingress", m, kind.key_of(M, "u1")) for m in how)
    else:
        assert not any(_allows(by_name["unit-u1"], "ingress", m, kind.key_of(M, "u1")) for m in how)


@pytest.mark.parametrize("kind", STORED, ids=lambda k: k.name)
def test_each_stored_kind_has_its_table_and_comes_back_from_the_store(kind, tmp_path):
    st = kind.store
    assert st is not None and TABLES[st.table] == (st.key_column, len(st.columns))
    msg = _example(kind)
    store = Store(tmp_path)
    try:
        store.commit_inputs([kind.put("x1", msg), Tick(0.0)], 1000.0, None)
        back = [i for i in store.restore(1000.0).inputs if kinds.ident(i) == "x1"]
        assert [type(i) for i in back] == [kind.put]
        assert kinds.message(back[0]) == msg or getattr(msg, "ttl_s", None) is not None  # TTL: the time left
        store.commit_inputs([kind.remove("x1")], 1001.0, None)
        assert store.restore(1001.0).inputs == []
    finally:
        store.close()


def test_the_restored_event_counts_every_stored_kind_by_name(tmp_path):
    store = Store(tmp_path)
    try:
        store.commit_inputs([k.put(f"x{i}", _example(k)) for i, k in enumerate(STORED)], 1000.0, None)
        kept = store.restore(1000.0).kept
    finally:
        store.close()
    assert kept == {k.name: 1 for k in STORED}
    ev = RestoredEvent.counted(kept, planner="p1", missions=0, expired=0)
    back = decode_event(encode(ev))  # a kind's name is a valid key of the wire's ``kinds``
    assert isinstance(back, RestoredEvent) and back.kinds == kept
    assert (back.threats, back.goals, back.zones, back.teams) == (1, 1, 1, 1)  # older readers' fields


def test_a_units_rows_are_restored_after_the_rest_and_as_its_mission_where_recorded(tmp_path):
    assert [k.store.per_unit for k in STORED if k.store] == sorted(
        k.store.per_unit for k in STORED if k.store
    )
    goal = next(k for k in STORED if k.store and k.store.per_unit)
    threat = next(k for k in STORED if k.store and not k.store.per_unit)
    store = Store(tmp_path)
    try:
        store.commit_inputs(
            [goal.put("u1", _example(goal)), threat.put("t1", _example(threat))], 1000.0, None
        )
        restored = store.restore(1000.0).inputs
        assert [type(i) for i in restored] == [threat.put, goal.put]
    finally:
        store.close()
    assert any(MissionRestored in k.inputs for k in STORED if k.store and k.store.per_unit)


@pytest.mark.parametrize("kind", WRITES, ids=lambda k: k.name)
def test_every_write_is_logged_and_refused_on_its_key_when_the_store_fails(kind):
    put, gone = kind.put("x1", _example(kind)), kind.remove("x1")
    line, gone_line = kinds.log_line(put), kinds.log_line(gone)
    assert line is not None and gone_line is not None and "x1" in line.args and "x1" in gone_line.args
    assert line.what.startswith(kind.name)
    assert line.at is not None or kind.key is keys.KeyKind.TEAM  # a team has no position of its own
    err = InputError("$", "not stored")
    for inp in (put, gone):
        refused = kinds.rejected(inp, M, err)
        assert isinstance(refused, InputRejected) and refused.kind is kind.key
        assert refused.key == kind.key_of(M, "x1")
    assert kinds.rejected(Tick(0.0), M, err) == Tick(0.0)


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_blame_names_the_key_each_input_came_on(kind):
    for cls in kind.inputs:
        names = [f for f in cls.__dataclass_fields__]
        inp = cls.__new__(cls)
        for f in names:
            object.__setattr__(inp, f, "u1" if f == names[0] else None)
        key, unit, kk = kinds.blame(inp, M)
        assert keys.parse(key) == keys.Key(kind.key, M, "u1") and kk is kind.key
        assert unit == ("u1" if kind.blames_unit else None)
    assert kinds.blame(Tick(1.0), M) == (keys.event(M, "tick"), None, keys.KeyKind.EVENT)
    rejected = InputRejected("not/a/key", InputError("key", "x"))
    assert kinds.blame(rejected, M) == ("not/a/key", None, None)


def _doc_rows() -> dict[str, tuple[str, str]]:
    rows = {}
    for line in DOCS.read_text().splitlines():
        m = re.match(r"^\| `([^`]+)` \| ([^|]+) \| (.*) \|$", line)
        if m:
            rows[m[1]] = (m[2].strip(), m[3])
    return rows


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_the_docs_key_table_has_each_kind_with_its_schema(kind):
    rows = _doc_rows()
    assert keys.template(kind.key) in rows, f"docs/wire.md: no row for {keys.template(kind.key)}"
    who, payload = rows[keys.template(kind.key)]
    if kind.schema is not None:
        assert f"(../schemas/{kind.schema}.schema.json)" in payload
    else:
        assert who == "liveliness token"
    if kind.mode == "write":
        assert who == "any → planner" and "a DELETE" in payload


@pytest.mark.parametrize("kind", WRITES, ids=lambda k: k.name)
def test_the_world_has_a_handler_for_each_write_kinds_put_and_remove(kind):
    from pfp_service.world.world import World

    w = World(WorldSettings(mission=M))
    for inp in (kind.put("x1", _example(kind)), kind.remove("x1")):
        out = w.apply([inp], 0.0)  # an input no case takes is a fault (``_apply_one``'s last case)
        assert not out.faults, out.faults


def test_the_docs_list_of_files_a_new_kind_touches_names_real_files_and_at_most_six():
    text = (ROOT / "docs" / "development.md").read_text()
    said = re.search(r"A new write kind \(.*?\) is these edits, (\d+) files:\n\n(.*?)\n\n", text, re.S)
    assert said, "docs/development.md: no 'A new write kind ... is these edits, N files:' list"
    files = re.findall(r"^\d+\. `([^`]+)`", said[2], re.M)
    assert len(files) == int(said[1]) <= 6
    for f in files:
        assert (ROOT / f).is_file(), f
    # each derived piece reads the table: none of the node's modules is on the list
    assert not any(f.startswith("pfp_service/node/") for f in files)


def _paged(world):
    """``world``'s pages as a peer answers them, one item of each list a page."""

    def ask(selector: str, _timeout_s: float) -> list[bytes]:
        q = decode_world_query(selector.partition("?")[2])
        page = world.snapshot(
            1.0,
            min(q.units_limit, 1),
            q.units_from,
            q.threats_from,
            threats_limit=min(q.threats_limit, 1),
            zones_from=q.zones_from,
            zones_limit=min(q.zones_limit, 1),
            writes_from=q.writes_from,
            writes_limit=min(q.writes_limit, 1),
        )
        return [encode(page)]

    return ask


@pytest.mark.parametrize("kind", WRITES, ids=lambda k: k.name)
def test_a_joining_planner_learns_each_write_kind_from_a_peers_pages(kind):
    from pfp_service.node.worldpages import fetch_world
    from pfp_service.world.world import World

    def world(pid: str) -> World:
        return World(WorldSettings(mission=M, planner_id=pid))

    def held(w: World) -> dict[str, list[tuple[object, ...]]]:  # each list's ids and time left (a put's
        s = w.snapshot(1.0)  # own ttl_s is the time left once learnt), and each unit's goal
        return {
            "units": [(u.id, u.goal) for u in s.units],
            "threats": [(t.id, t.ttl_s) for t in s.threats],
            "zones": [(z.id, z.ttl_s) for z in s.zones],
            "writes": [(x.kind, x.id, x.ttl_s) for x in s.writes],
        }

    peer, empty = world("p1"), world("p1")
    peer.apply([kind.put("x1", _example(kind))], 0.0)
    assert held(peer) != held(empty), f"{kind.name}: not in the world snapshot (a list, or Kind.held)"
    joined = fetch_world(_paged(peer), M, "p2")
    assert joined.complete and joined.inputs
    learnt = world("p2")
    learnt.apply(joined.inputs, 1.0)  # at the time the pages were read: the same time left
    assert held(learnt) == held(peer)
