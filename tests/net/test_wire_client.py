"""A client written only from ``schemas/``: a raw zenoh session plus ``json``, against a real router.

The client half (``CLIENT`` below) reads nothing of pfp_service: keys come from
``schemas/index.json``, payloads are dicts written from the schema files, and a
minimal JSON Schema check (the keywords ``schemas/`` uses) validates them.  The
planner half is a router-mode session that decodes with ``pfp_service.wire``,
as the daemon will.  Real sessions on 127.0.0.1, a free port, multicast off.
"""

from __future__ import annotations

import json
import math
import queue
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.zenoh_util import free_port

pytestmark = pytest.mark.net

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "schemas"
TIMEOUT_S = 5.0

# ============================ CLIENT: only schemas/, zenoh and json ============================
INDEX = json.loads((SCHEMAS / "index.json").read_text())
ENCODING = zenoh.Encoding(INDEX["encoding"])
MISSION = "trial-1"


def key_for(message: str, **chunks: str) -> str:
    return INDEX["messages"][message]["key"].format(mission=MISSION, **chunks)


def schema_of(message: str) -> dict[str, Any]:
    return json.loads((SCHEMAS / INDEX["messages"][message]["schema"]).read_text())


def example(rel: str) -> dict[str, Any]:
    return json.loads((SCHEMAS / rel).read_text())


_TYPES: dict[str, Callable[[Any], bool]] = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v),
    "boolean": lambda v: isinstance(v, bool),
    "null": lambda v: v is None,
}


def problems(value: Any, node: dict[str, Any], root: dict[str, Any], path: str = "$") -> list[str]:
    """JSON Schema (2020-12) errors of ``value``, for the keywords the published schemas use."""
    if "$ref" in node:
        node = {
            **root["$defs"][node["$ref"].removeprefix("#/$defs/")],
            **{k: v for k, v in node.items() if k != "$ref"},
        }
    if "anyOf" in node and all(problems(value, alt, root, path) for alt in node["anyOf"]):
        return [f"{path}: matches none of anyOf"]
    out: list[str] = []
    if "type" in node and not _TYPES[node["type"]](value):
        return [f"{path}: expected {node['type']}"]
    if "enum" in node and value not in node["enum"]:
        out.append(f"{path}: not one of {node['enum']}")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        for kw, ok in (
            ("minimum", value >= node.get("minimum", -math.inf)),
            ("maximum", value <= node.get("maximum", math.inf)),
            ("exclusiveMinimum", value > node.get("exclusiveMinimum", -math.inf)),
        ):
            if not ok:
                out.append(f"{path}: violates {kw}")
    if isinstance(value, str):
        if "pattern" in node and not re.search(node["pattern"], value):
            out.append(f"{path}: does not match {node['pattern']}")
        if len(value) > node.get("maxLength", math.inf):
            out.append(f"{path}: too long")
    if isinstance(value, list):
        if not node.get("minItems", 0) <= len(value) <= node.get("maxItems", math.inf):
            out.append(f"{path}: wrong number of items")
        prefix = node.get("prefixItems", [])
        for i, item in enumerate(value):
            sub = prefix[i] if i < len(prefix) else node.get("items", True)
            if sub is False:
                out.append(f"{path}[{i}]: not allowed")
            elif isinstance(sub, dict):
                out += problems(item, sub, root, f"{path}[{i}]")
    if isinstance(value, dict):
        out += [f"{path}.{name}: required" for name in node.get("required", []) if name not in value]
        for name, sub in node.get("properties", {}).items():
            if name in value:
                out += problems(value[name], sub, root, f"{path}.{name}")
    return out


def check(message: str, value: Any) -> None:
    doc = schema_of(message)
    assert problems(value, doc, doc) == [], (message, value)


# Written by hand from the schema files, as a client in another language would.
BUILT: dict[str, list[dict[str, Any]]] = {
    "unit_state": [
        {"position": [12.5, -3.0]},
        {
            "position": [12.5, -3.0],
            "t": 1767225600.25,
            "seq": 7,
            "kind": "manned",
            "speed_mps": 4.2,
            "heading_deg": 270,
        },
    ],
    "goal": [{"position": [100, 50]}, {"position": [100, 50], "delta": 2.0, "tolerance": 0.5, "step": 0.25}],
    "team": [
        {"members": ["m1", "r1"]},
        {
            "lead": "r1",
            "follow": ["m1"],
            "standoff_m": 300,
            "corridor_m": 30,
            "controller": "m1",
            "robots": ["r1"],
        },
    ],
    "threat": [
        {"position": [40, 20], "sigma_range": 8, "sigma_lateral": 3},
        {
            "position": [40, 20],
            "facing_deg": -90,
            "sigma_range": 8,
            "sigma_lateral": 3,
            "skew": 4,
            "weight": 2,
            "ttl_s": 60,
        },
    ],
    "zone": [
        {"polygon": [[[0, 0], [30, 0], [30, 10], [0, 10], [0, 0]]]},
        {
            "kind": "keep_out",
            "polygon": [
                [[0, 0], [60, 0], [60, 60], [0, 60], [0, 0]],
                [[20, 20], [40, 20], [40, 40], [20, 40], [20, 20]],
            ],
            "ttl_s": 600,
        },
        {"circle": {"centre": [50, -20], "radius_m": 12.5}},
    ],
    "team_preview_request": [{}, {"horizon_s": 120, "dt_s": 0.25, "speeds": {"r1": 3.0}}],
    "team_preview": [
        {"team": "alpha"},
        {
            "team": "alpha",
            "eta_s": 95.5,
            "members": [
                {
                    "unit": "m1",
                    "speed_mps": 2,
                    "points": [[0, 59, 0], [95.5, 239.3, 0.1]],
                    "statuses": [
                        {"t_s": 0, "status": "en_route"},
                        {"t_s": 95.5, "status": "arrived", "reason": ""},
                    ],
                    "arrived_s": 95.5,
                }
            ],
            "simulated_s": 95.5,
            "stopped": "arrived",
            "outsiders": ["a1", "x7"],
            "outsiders_left_out": 2,
        },
    ],
    "preview_request": [
        {},
        {"goal": [5, 5], "max_iter": 500},
        {
            "threats": [{"id": "what-if_1", "position": [3, 3], "sigma_range": 1, "sigma_lateral": 1}],
            "step": 0.1,
        },
    ],
    "direction": [
        {"unit": "ugv-7", "status": "no_goal", "vector": [0, 0]},
        {
            "unit": "ugv-7",
            "seq": 7,
            "status": "escaping",
            "vector": [0.0, -1.0],
            "heading_deg": 180,
            "distance_to_goal": 55.5,
            "threat_level": 0.4,
            "lookahead": [[12.5, -3.1], [12.5, -3.2]],
            "reason": "escape: contour",
        },
    ],
    "error_reply": [{"error": "must be > 0", "field": "$.threats[0].sigma_range"}],
    "planner_status": [{"planner": "p-1", "mission": MISSION, "uptime_s": 1.5}],
    "event": [
        {"kind": "rejected", "key": "x", "reason": "bad"},
        {"kind": "replan", "units": ["ugv-7"], "reason": "threat t1 moved", "t": 1767225600.0},
        {"kind": "trapped", "unit": "ugv-7", "position": [1, 2]},
        {"kind": "arrived", "unit": "ugv-7", "position": [1, 2], "distance_to_goal": 0.01},
        {"kind": "stale", "unit": "ugv-7", "position": [1, 2], "reason": "silent for 10 s"},
        {"kind": "forgotten", "unit": "ugv-7", "stale_s": 600},
    ],
    "preview_reply": [],  # only planners build these; the example stands in
    "mission": [
        {
            "goal": {"position": [10, 10]},
            "origin": [0, 0],
            "params": {
                "delta": 1.0,
                "step": 0.1,
                "max_iter": 1000,
                "tolerance": 0.075,
                "intensity": "peak",
                "escape": "auto",
                "trap_window": 20,
                "progress_window": 200,
            },
        }
    ],
    "world_snapshot": [
        {"planner": "p-1", "mission": MISSION},
        {
            "planner": "p-1",
            "mission": MISSION,
            "units": [{"id": "ugv-7", "status": "en_route", "position": [1, 2], "last_seen_s": 0.5}],
            "threats": [{"id": "t1", "threat": {"position": [4, 6], "sigma_range": 1, "sigma_lateral": 1}}],
            "units_total": 1,
            "threats_total": 1,
        },
    ],
}


def all_messages() -> Iterator[tuple[str, dict[str, Any]]]:
    for name, entry in INDEX["messages"].items():
        for body in BUILT[name]:
            yield name, body
        for rel in entry["examples"]:
            yield name, example(rel)


# ============================ the planner side and the sessions ============================
def _config(mode: str, endpoints_key: str, endpoint: str) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5(endpoints_key, json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


@pytest.fixture(scope="module")
def sessions() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(_config("router", "listen/endpoints", endpoint))
    try:
        client = zenoh.open(_config("client", "connect/endpoints", endpoint))
        try:
            yield router, client
        finally:
            client.close()
    finally:
        router.close()


def _until(action: Callable[[], None], inbox: queue.Queue[Any], want: Callable[[Any], bool]) -> Any:
    """Repeat ``action`` until ``inbox`` yields an item ``want``s: declarations propagate asynchronously."""
    for _ in range(int(TIMEOUT_S / 0.05)):
        action()
        try:
            while True:
                item = inbox.get(timeout=0.05)
                if want(item):
                    return item
        except queue.Empty:
            continue
    raise AssertionError("nothing arrived in time")


def test_every_built_message_and_example_satisfies_its_schema() -> None:
    seen = set()
    for name, body in all_messages():
        check(name, body)
        seen.add(name)
    assert seen == set(INDEX["messages"])


@pytest.mark.parametrize(
    ("message", "bad"),
    [
        ("unit_state", {"position": [1]}),
        ("unit_state", {"position": [1, 2], "kind": "robot"}),
        ("threat", {"position": [0, 0], "sigma_range": 0, "sigma_lateral": 1}),
        ("direction", {"unit": "a b", "status": "en_route", "vector": [0, 0]}),
        ("event", {"kind": "rejected", "key": "k"}),
    ],
)
def test_the_schema_check_can_fail(message: str, bad: dict[str, Any]) -> None:
    doc = schema_of(message)
    assert problems(bad, doc, doc)


def test_client_puts_reach_the_planner_and_decode(sessions: tuple[zenoh.Session, zenoh.Session]) -> None:
    from pfp_service.wire import decode_goal, decode_threat, decode_unit_state, decode_zone, keys

    router, client = sessions
    inbox: queue.Queue[tuple[str, zenoh.SampleKind, bytes, str]] = queue.Queue()
    sub = router.declare_subscriber(
        keys.mission_all(MISSION),
        lambda s: inbox.put((str(s.key_expr), s.kind, s.payload.to_bytes(), str(s.encoding))),
    )
    try:
        probe = key_for("unit_state", unit="probe")
        _until(
            lambda: client.put(probe, b'{"position":[0,0]}', encoding=ENCODING),
            inbox,
            lambda i: i[0] == probe,
        )
        decoders = {
            "unit_state": decode_unit_state,
            "goal": decode_goal,
            "threat": decode_threat,
            "zone": decode_zone,
        }
        sent = 0
        for name, body in all_messages():
            if name not in decoders:
                continue
            chunk = {name: f"{name[0]}{sent}"} if name in ("threat", "zone") else {"unit": f"u{sent}"}
            key = key_for(name, **chunk)
            client.put(key, json.dumps(body), encoding=ENCODING)
            sent += 1
            got_key, kind, payload, encoding = inbox.get(timeout=TIMEOUT_S)
            while got_key == probe:
                got_key, kind, payload, encoding = inbox.get(timeout=TIMEOUT_S)
            assert (got_key, kind, encoding) == (key, zenoh.SampleKind.PUT, "application/json")
            assert keys.parse(got_key).kind.value == {"unit_state": "unit_state", "goal": "unit_goal"}.get(
                name, name
            )
            decoders[name](payload)
        assert sent >= 7
        for name, chunk in (("goal", {"unit": "u1"}), ("threat", {"threat": "t9"}), ("zone", {"zone": "z9"})):
            client.delete(key_for(name, **chunk))
            got_key, kind, payload, _ = inbox.get(timeout=TIMEOUT_S)
            assert (got_key, kind, payload) == (key_for(name, **chunk), zenoh.SampleKind.DELETE, b"")
    finally:
        sub.undeclare()


def test_planner_puts_reach_the_client_and_satisfy_the_schema(
    sessions: tuple[zenoh.Session, zenoh.Session],
) -> None:
    from pfp_service.wire import decode_direction, decode_event, encode, keys
    from pfp_service.wire.encoding import zenoh_encoding

    router, client = sessions
    inbox: queue.Queue[tuple[str, bytes, str]] = queue.Queue()
    subs = [
        client.declare_subscriber(
            key_for(name, **chunk),
            lambda s: inbox.put((str(s.key_expr), s.payload.to_bytes(), str(s.encoding))),
        )
        for name, chunk in (("direction", {"unit": "ugv-7"}), ("event", {"kind": "*"}))
    ]
    try:
        probe = keys.event(MISSION, "probe")
        _until(lambda: router.put(probe, b"{}", encoding=zenoh_encoding()), inbox, lambda i: i[0] == probe)
        for name, body in all_messages():
            if name not in ("direction", "event"):
                continue
            # the planner side: decode what a client would build, re-encode as the daemon will
            if name == "direction":
                msg: Any = decode_direction(json.dumps({**body, "unit": "ugv-7"}).encode())
                key = keys.unit_direction(MISSION, msg.unit)
            else:
                msg = decode_event(json.dumps(body).encode())
                key = keys.event(MISSION, body["kind"])
            router.put(key, encode(msg), encoding=zenoh_encoding())
            got_key, payload, encoding = inbox.get(timeout=TIMEOUT_S)
            while got_key == probe:
                got_key, payload, encoding = inbox.get(timeout=TIMEOUT_S)
            assert (got_key, encoding) == (key, INDEX["encoding"])
            check(name, json.loads(payload))
            if name == "event":
                assert got_key.rsplit("/", 1)[1] == json.loads(payload)["kind"]
    finally:
        for s in subs:
            s.undeclare()


def test_queries_preview_status_and_errors(sessions: tuple[zenoh.Session, zenoh.Session]) -> None:
    from pfp_service.errors import InputError
    from pfp_service.wire import (
        ErrorReply,
        PlannerStatus,
        decode_preview_request,
        encode,
        keys,
    )
    from pfp_service.wire.encoding import zenoh_encoding

    router, client = sessions
    reply_body = (SCHEMAS / INDEX["messages"]["preview_reply"]["examples"][0]).read_bytes()
    asked: queue.Queue[Any] = queue.Queue()

    def on_preview(query: zenoh.Query) -> None:  # decode and answer; nothing blocks here
        try:
            req = decode_preview_request(query.payload.to_bytes() if query.payload is not None else None)
        except InputError as exc:
            query.reply_err(encode(ErrorReply.of(exc)), encoding=zenoh_encoding())
            return
        asked.put(req)
        query.reply(query.key_expr, reply_body, encoding=zenoh_encoding())

    def on_status(query: zenoh.Query) -> None:
        status = PlannerStatus(planner="p-1", mission=MISSION, uptime_s=2.0, units=1)
        query.reply(query.key_expr, encode(status), encoding=zenoh_encoding())

    qs = [
        router.declare_queryable(keys.previews(MISSION), on_preview),
        router.declare_queryable(keys.planner_status(MISSION, "p-1"), on_status),
    ]

    def ask(key: str, payload: bytes | None = None) -> list[zenoh.Reply]:
        querier = client.declare_querier(key, timeout=TIMEOUT_S)
        matched: queue.Queue[bool] = queue.Queue()
        listener = querier.declare_matching_listener(lambda status: matched.put(status.matching))
        try:
            # A queryable's declaration reaches the client asynchronously: wait for it, not a sleep.
            if not querier.matching_status.matching:  # type: ignore[attr-defined]  # stub says bool
                assert matched.get(timeout=TIMEOUT_S), f"no planner serves {key}"
            return list(querier.get(payload=payload, encoding=ENCODING))
        finally:
            listener.undeclare()
            querier.undeclare()

    try:
        for body in [None, *[json.dumps(b).encode() for b in BUILT["preview_request"]]]:
            (reply,) = ask(key_for("preview_request", unit="ugv-7"), body)
            assert reply.ok is not None, reply.err
            check("preview_reply", json.loads(reply.ok.payload.to_bytes()))
            assert str(reply.ok.encoding) == INDEX["encoding"]
            asked.get(timeout=TIMEOUT_S)
        bad = {"threats": [{"id": "a", "position": [0, 0], "sigma_range": -1, "sigma_lateral": 1}]}
        (reply,) = ask(key_for("preview_request", unit="ugv-7"), json.dumps(bad).encode())
        assert reply.err is not None
        err = json.loads(reply.err.payload.to_bytes())
        check("error_reply", err)
        assert err == {"error": "must be >= 0.001", "field": "$.threats[0].sigma_range"}
        (reply,) = ask(key_for("planner_status", planner="p-1"))
        assert reply.ok is not None
        status = json.loads(reply.ok.payload.to_bytes())
        check("planner_status", status)
        assert status["units"] == 1
    finally:
        for q in qs:
            q.undeclare()


def test_liveliness_tokens_name_the_unit(sessions: tuple[zenoh.Session, zenoh.Session]) -> None:
    from pfp_service.wire import keys

    router, client = sessions
    inbox: queue.Queue[tuple[str, zenoh.SampleKind]] = queue.Queue()
    sub = router.liveliness().declare_subscriber(
        keys.alive_units(MISSION), lambda s: inbox.put((str(s.key_expr), s.kind)), history=True
    )
    try:
        key = INDEX["liveliness"]["alive_unit"].format(mission=MISSION, unit="ugv-7")
        token = client.liveliness().declare_token(key)
        got, kind = inbox.get(timeout=TIMEOUT_S)
        assert kind == zenoh.SampleKind.PUT
        assert keys.parse(got) == keys.Key(keys.KeyKind.ALIVE_UNIT, MISSION, "ugv-7")
        token.undeclare()
        assert inbox.get(timeout=TIMEOUT_S) == (key, zenoh.SampleKind.DELETE)
    finally:
        sub.undeclare()
