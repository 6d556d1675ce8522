"""Key expressions: builders, parser, wildcards, and that no topic string lives outside keys.py."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.wire.keys import Key, KeyKind

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]
chunk = st.from_regex(r"\A[A-Za-z0-9_-]{1,64}\Z")

BUILDERS = {
    KeyKind.UNIT_STATE: (keys.unit_state, keys.unit_states, "mumt/m1/unit/u1/state"),
    KeyKind.UNIT_GOAL: (keys.unit_goal, keys.goals, "mumt/m1/unit/u1/goal"),
    KeyKind.UNIT_DIRECTION: (keys.unit_direction, keys.unit_directions, "mumt/m1/unit/u1/direction"),
    KeyKind.UNIT_MISSION: (keys.unit_mission, keys.unit_missions, "mumt/m1/unit/u1/mission"),
    KeyKind.THREAT: (keys.threat, keys.threats, "mumt/m1/threat/u1"),
    KeyKind.PREVIEW: (keys.preview, keys.previews, "mumt/m1/preview/u1"),
    KeyKind.PLANNER_STATUS: (keys.planner_status, keys.planner_statuses, "mumt/m1/planner/u1/status"),
    KeyKind.EVENT: (keys.event, keys.events, "mumt/m1/event/u1"),
    KeyKind.ALIVE_UNIT: (keys.alive_unit, keys.alive_units, "mumt/m1/alive/unit/u1"),
    KeyKind.ALIVE_PLANNER: (keys.alive_planner, keys.alive_planners, "mumt/m1/alive/planner/u1"),
    KeyKind.WORLD: (keys.world, keys.worlds, "mumt/m1/planner/u1/world"),
    KeyKind.ZONE: (keys.zone, keys.zones, "mumt/m1/zone/u1"),
    KeyKind.TEAM: (keys.team, keys.teams, "mumt/m1/team/u1"),
    KeyKind.TEAM_PREVIEW: (keys.team_preview, keys.team_previews, "mumt/m1/preview/team/u1"),
}


def test_every_kind_has_a_builder_and_a_wildcard() -> None:
    assert set(BUILDERS) == set(KeyKind)


@pytest.mark.parametrize("kind", list(KeyKind))
def test_builders_spell_the_documented_layout(kind: KeyKind) -> None:
    build, wild, expected = BUILDERS[kind]
    assert build("m1", "u1") == expected
    assert wild("m1") == expected.replace("u1", "*", 1).replace("mumt/m1", "mumt/m1")
    assert keys.parse(expected) == Key(kind, "m1", "u1")


@pytest.mark.parametrize("kind", list(KeyKind))
def test_wildcards_match_their_own_kind_only(kind: KeyKind) -> None:
    _, wild, _ = BUILDERS[kind]
    sub = zenoh.KeyExpr(wild("m1"))
    for other, (build, _, _) in BUILDERS.items():
        assert sub.intersects(zenoh.KeyExpr(build("m1", "x_9"))) == (other is kind), other
        assert not sub.intersects(zenoh.KeyExpr(build("m2", "x_9")))


def test_mission_all_covers_every_key_of_the_mission() -> None:
    everything = zenoh.KeyExpr(keys.mission_all("m1"))
    for build, _, _ in BUILDERS.values():
        assert everything.intersects(zenoh.KeyExpr(build("m1", "a")))
        assert not everything.intersects(zenoh.KeyExpr(build("m2", "a")))


@given(kind=st.sampled_from(list(KeyKind)), mission=chunk, ident=chunk)
def test_parse_inverts_every_builder(kind: KeyKind, mission: str, ident: str) -> None:
    build, _, _ = BUILDERS[kind]
    key = build(mission, ident)
    zenoh.KeyExpr(key)  # a valid Zenoh key expression, no wildcard or $ in it
    assert keys.parse(key) == Key(kind, mission, ident)


@pytest.mark.parametrize("bad", ["", "a/b", "*", "**", "a b", "x$y", "ü", "a" * 65, "u.1", "a?b"])
def test_builders_refuse_bad_chunks(bad: str) -> None:
    with pytest.raises(InputError) as e:
        keys.unit_state("default", bad)
    assert e.value.path == "unit"
    with pytest.raises(InputError) as e:
        keys.threat(bad, "t1")
    assert e.value.path == "mission"
    with pytest.raises(InputError):
        keys.unit_states(bad)


@given(kind=st.sampled_from(list(KeyKind)), mission=chunk, ident=chunk)
def test_key_of_agrees_with_parse_and_the_builders(kind: KeyKind, mission: str, ident: str) -> None:
    build, _, _ = BUILDERS[kind]
    of = keys.KeyOf(kind, mission)
    assert of.key(ident) == build(mission, ident)
    assert of.id(build(mission, ident)) == ident


@pytest.mark.parametrize(
    "key",
    [
        "mumt/m1/unit/a b/state",
        "mumt/m1/unit//state",
        "mumt/m1/unit/u1/goal",  # another kind
        "mumt/m2/unit/u1/state",  # another mission
        "mumt/m1/unit/" + "u" * 65 + "/state",
        "mumt/m1/unit/" + "u/" * 200 + "/state",
        "mumt/m1/threat/t1",
    ],
)
def test_key_of_refuses_what_is_not_its_kind(key: str) -> None:
    with pytest.raises(InputError) as e:
        keys.KeyOf(KeyKind.UNIT_STATE, "m1").id(key)
    assert e.value.path == "key"
    with pytest.raises(InputError):
        keys.KeyOf(KeyKind.UNIT_DIRECTION, "m1").key("a b")


def test_the_longest_chunks_are_fine() -> None:
    assert keys.parse(keys.threat("m" * 64, "t" * 64)).id == "t" * 64


@pytest.mark.parametrize(
    "key",
    [
        "mumt/default/unit/u1",
        "mumt/default/unit/u1/state/extra",
        "mumt/default/unit/*/state",
        "mumt/default/unit/a b/state",
        "other/default/unit/u1/state",
        "mumt/default/threat/t1/x",
        "mumt/default/event",
        "mumt/" + "m" * 65 + "/threat/t1",
        "mumt/default/alive/robot/u1",
        "",
    ],
)
def test_parse_rejects_keys_outside_the_layout(key: str) -> None:
    with pytest.raises(InputError) as e:
        keys.parse(key)
    assert e.value.path == "key"


def test_parse_accepts_a_zenoh_key_expr() -> None:
    ke = zenoh.KeyExpr(keys.unit_goal("default", "tank-2"))
    assert keys.parse(ke) == Key(KeyKind.UNIT_GOAL, "default", "tank-2")  # type: ignore[arg-type]


def test_default_mission_and_templates_are_published() -> None:
    assert keys.DEFAULT_MISSION == "default"
    index = json.loads((ROOT / "schemas" / "index.json").read_text())
    published = {e["key"] for e in index["messages"].values() if e["key"]} | set(index["liveliness"].values())
    assert published == {keys.template(k) for k in KeyKind}
    assert index["chunk_pattern"] == keys.CHUNK_PATTERN


def _string_constants(tree: ast.AST) -> list[tuple[int, str]]:
    docstrings = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                docstrings.add(id(body[0].value))
    return [
        (n.lineno, n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docstrings
    ]


def test_no_topic_string_outside_keys_py() -> None:
    """Style rule 6: one module builds key expressions (docstrings may mention them)."""
    offenders = []
    sources = [*(ROOT / "pfp_service").rglob("*.py"), *(ROOT / "clients").rglob("*.py")]
    for path in sorted(sources):
        if path == ROOT / "pfp_service" / "wire" / "keys.py":
            continue
        for line, text in _string_constants(ast.parse(path.read_text(encoding="utf-8"))):
            if "mumt/" in text or text.startswith("mumt"):
                offenders.append(f"{path.relative_to(ROOT)}:{line}: {text!r}")
    assert not offenders, "key strings outside pfp_service/wire/keys.py:\n" + "\n".join(offenders)
    assert len(sources) > 5


def test_the_topic_scan_sees_code_but_not_docstrings() -> None:
    src = (
        '"""mumt/{m}/unit in a docstring"""\n\ndef f():\n    """mumt/x too"""\n    return "mumt/a/b" + KEY\n'
    )
    assert [text for _, text in _string_constants(ast.parse(src))] == ["mumt/a/b"]
