"""Wire messages: every field's bad values and boundary values (whole payloads and sizes: ``test_wire_payloads``; bounds and versions: ``test_wire_compat``)."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable, Iterator
from typing import Any

import msgspec
import pytest

from pfp_service.errors import InputError
from pfp_service.wire import messages as m
from pfp_service.wire.contract import examples

BIG = 7.77e77  # written as 1e999 on the wire: parses to infinity
MISSING = object()
REQ, OPT, DEF = "required", "optional (null allowed)", "defaulted (null not allowed)"
# Required by the default threat shape (skew_normal) only: optional in the type, and null counts as absent.
SHAPE_REQ = "required by the skew_normal shape"


def _base() -> dict[str, Any]:
    ex = {name: json.loads(m.encode(obj)) for group in examples().values() for name, obj in group}
    ex["what_if_threat"] = ex["preview_request"]["threats"][0]
    return ex


BASES = _base()

DECODERS: dict[str, Callable[[bytes], Any]] = {
    "unit_state": m.decode_unit_state,
    "goal": m.decode_goal,
    "threat": m.decode_threat,
    "preview_request": m.decode_preview_request,
    "what_if_threat": m.decode_preview_request,
    "direction": m.decode_direction,
    "error_reply": m.decode_error_reply,
    "planner_status": m.decode_planner_status,
    "event.rejected": m.decode_event,
    "event.replan": m.decode_event,
    "event.trapped": m.decode_event,
    "event.arrived": m.decode_event,
}
TYPES: dict[str, type] = {
    "unit_state": m.UnitState,
    "goal": m.Goal,
    "threat": m.ThreatUpdate,
    "preview_request": m.PreviewRequest,
    "what_if_threat": m.WhatIfThreat,
    "direction": m.Direction,
    "error_reply": m.ErrorReply,
    "planner_status": m.PlannerStatus,
    "event.rejected": m.RejectedEvent,
    "event.replan": m.ReplanEvent,
    "event.trapped": m.TrappedEvent,
    "event.arrived": m.ArrivedEvent,
}

# Bad values by field type: (value, sub-path, fragment of the reason).
FINITE = [("1", "", "expected a finite number"), (True, "", "got bool")]
BAD: dict[str, list[tuple[Any, str, str]]] = {
    "point": [
        ("1,2", "", "expected array, got str"),
        ({"x": 1, "y": 2}, "", "expected array, got object"),
        ([1.0], "", "expected array of length 2"),
        ([1.0, 2.0, 3.0], "", "expected array of length 2"),
        ([BIG, 0.0], "[0]", "expected a finite number"),
        ([0.0, -BIG], "[1]", "expected a finite number"),
        ([2e9, 0.0], "[0]", "expected a finite number within ±1e+09"),
        ([0.0, "x"], "[1]", "expected a finite number, got str"),
        ([0.0, None], "[1]", "expected a finite number, got null"),
    ],
    # An infinity (1e999) fails the upper bound, which the reason names.
    "angle": [
        *FINITE,
        (BIG, "", "must be <= 360"),
        (360.5, "", "must be <= 360"),
        (-361, "", "must be >= -360"),
    ],
    "positive": [
        *FINITE,
        (BIG, "", "expected a finite number"),
        (-BIG, "", "must be > 0"),
        (0, "", "must be > 0"),
        (-1.5, "", "must be > 0"),
        (2e9, "", "finite number within"),
    ],
    # a step or a tolerance: a millimetre at least (constraints.LENGTH_MIN_M), so never subnormal
    "length": [
        *FINITE,
        (BIG, "", "expected a finite number"),
        (-BIG, "", "must be >= 0.001"),
        (0, "", "must be >= 0.001"),
        (5e-324, "", "must be >= 0.001"),
        (1e-300, "", "must be >= 0.001"),
        (0.0009, "", "must be >= 0.001"),
        (2e9, "", "finite number within"),
    ],
    "delta": [
        *FINITE,
        (BIG, "", "expected a finite number"),
        (0, "", "must be >= 1e-09"),
        (5e-324, "", "must be >= 1e-09"),
        (-1, "", "must be >= 1e-09"),
        (2e9, "", "finite number within"),
    ],
    "origin": [
        ("x", "", "expected object"),
        ({"lat": 95.0, "lon": 0.0}, ".lat", "must be < 89.9"),
        ({"lat": 0.0}, ".lon", "is required"),
    ],
    "terrain": [
        ("x", "", "expected object"),
        ({"file": "a.tif"}, ".sha256", "is required"),
    ],
    "sigma": [
        *FINITE,
        (BIG, "", "expected a finite number"),
        (-BIG, "", "must be >= 0.001"),
        (0, "", "must be >= 0.001"),
        (1e-170, "", "must be >= 0.001"),
        (2e9, "", "finite number within"),
    ],
    "nonneg": [
        *FINITE,
        (BIG, "", "finite number"),
        (-0.001, "", "must be >= 0"),
        (2e9, "", "finite number within"),
    ],
    "skew": [
        *FINITE,
        (BIG, "", "must be <= 1000"),
        (-0.1, "", "must be >= 0"),
        (1000.5, "", "must be <= 1000"),
    ],
    "weight": [
        *FINITE,
        (BIG, "", "must be <= 1e+06"),
        (-1, "", "must be >= 0"),
        (1e6 + 1, "", "must be <= 1e+06"),
    ],
    "speed": [
        *FINITE,
        (BIG, "", "must be <= 1000"),
        (-1, "", "must be >= 0"),
        (1000.1, "", "must be <= 1000"),
    ],
    "time": [
        *FINITE,
        (BIG, "", "must be <= 1e+11"),
        (-1, "", "must be >= 0"),
        (1e12, "", "must be <= 1e+11"),
    ],
    "count": [
        (-1, "", "must be >= 0"),
        (2**53, "", "must be <="),
        (1.5, "", "expected int"),
        ("1", "", "expected int"),
        (True, "", "got bool"),
    ],
    "iterations": [(0, "", "must be >= 1"), (10_000_001, "", "must be <="), (1.5, "", "expected int")],
    "shape": [
        ("Cone", "", "matching regex"),
        ("x" * 33, "", "matching regex"),
        (1, "", "expected str, got int"),
    ],
    # the skew-normal takes none: each case is refused before its shape is asked
    "shape_params": [
        ([1.0], "", "expected object, got array"),
        ({f"p{i}": 1.0 for i in range(17)}, "", "length must be <= 16"),
        ({"radius_m": "x"}, "[...]", "expected a finite number, got str"),
        ({"radius_m": 1.0}, "", "the skew_normal shape takes its fields at the top level"),
    ],
    "id": [
        ("", "", "matching regex"),
        ("a b", "", "matching regex"),
        ("a/b", "", "matching regex"),
        ("u*", "", "matching regex"),
        ("x" * 65, "", "matching regex"),
        (5, "", "expected str, got int"),
    ],
    "text": [
        ("x" * 1025, "", "length must be <= 1024"),
        (5, "", "expected str, got int"),
        ([], "", "expected str"),
    ],
    "unit_kind": [
        ("robot", "", "unknown value 'robot' (expected one of: manned, unmanned)"),
        (1, "", "expected str"),
    ],
    "status": [
        ("lost", "", "expected one of: en_route, escaping, arrived, trapped, no_goal"),
        (0, "", "expected str"),
    ],
    "points": [
        ("x", "", "expected array"),
        ([[0.0, 0.0]] * (m.MAX_LOOKAHEAD + 1), "", "length must be <= 1000"),
        ([[0.0, 0.0], [1.0]], "[1]", "expected array of length 2"),
        ([[0.0, BIG]], "[0][1]", "expected a finite number"),
    ],
    "route": [
        ("detour", "", "expected one of: , descent, lower_exposure, around_trap, escape, leave"),
        (0, "", "expected str"),
    ],
    "progress": [
        ("stuck", "", "expected one of: , moving, holding, stalled"),
        (0, "", "expected str"),
    ],
    "bool": [(1, "", "expected bool"), ("true", "", "expected bool")],
    "latlons": [
        ("x", "", "expected array"),
        ([{"lat": 0.0, "lon": 0.0}] * (m.MAX_LOOKAHEAD + 1), "", "length must be <= 1000"),
        ([{"lat": 91.0, "lon": 0.0}], "[0].lat", "must be <= 90"),
        ([{"lat": 0.0, "lon": -180.5}], "[0].lon", "must be >= -180"),
        ([{"lat": 0.0}], "[0].lon", "is required"),
        ([[0.0, 0.0]], "[0]", "expected object"),
    ],
    "changes": [
        ("t1", "", "expected array"),
        ([{"threat": "t1", "change": "moved"}], "[0].change", "matching regex"),
        ([{"change": "put"}], "[0].threat", "is required"),
    ],
    "texts": [
        ("p1", "", "expected array, got str"),
        ([3], "[0]", "expected str"),
        (["p"] * 65, "", "length must be <= 64"),
    ],
    "ids": [
        ("u1", "", "expected array, got str"),
        (["ok", "a b"], "[1]", "matching regex"),
        ([3], "[0]", "expected str"),
    ],
    "mobility": [
        ("foot", "", "expected object, got str"),
        ({}, ".class", "is required"),
        ({"class": "Foot!"}, ".class", "matching regex"),
        ({"class": "foot", "max_slope_deg": 0.5}, ".max_slope_deg", "must be >= 1"),
        ({"class": "foot", "max_slope_deg": 90}, ".max_slope_deg", "must be <= 89"),
    ],
    "whatif_threats": [
        ("t1", "", "expected array"),
        ([BASES["what_if_threat"]] * 2, "[1].id", "duplicate id 'ambush'"),
        (
            [{**BASES["what_if_threat"], "id": f"t{i}"} for i in range(m.MAX_WHATIF_THREATS + 1)],
            "",
            "length must be <= 256",
        ),
        ([{"position": [0, 0], "id": "w"}], "[0].sigma_range", "is required"),
    ],
}

# Every field of every message: its type in BAD, and whether it is required, nullable or defaulted.
THREAT_FIELDS = {
    "position": ("point", REQ),
    "shape": ("shape", DEF),
    "facing_deg": ("angle", DEF),
    "sigma_range": ("sigma", SHAPE_REQ),
    "sigma_lateral": ("sigma", SHAPE_REQ),
    "skew": ("skew", DEF),
    "params": ("shape_params", OPT),
    "weight": ("weight", DEF),
    "ttl_s": ("positive", OPT),
}
EVENT_FIELDS = {"planner": ("id", OPT), "t": ("time", OPT)}
FIELDS: dict[str, dict[str, tuple[str, str]]] = {
    "unit_state": {
        "position": ("point", REQ),
        "t": ("time", OPT),
        "seq": ("count", OPT),
        "kind": ("unit_kind", OPT),
        "speed_mps": ("speed", OPT),
        "heading_deg": ("angle", OPT),
        "mobility": ("mobility", OPT),
    },
    "goal": {
        "position": ("point", REQ),
        "delta": ("delta", OPT),
        "tolerance": ("length", OPT),
        "step": ("length", OPT),
        "mobility": ("mobility", OPT),
    },
    "threat": THREAT_FIELDS,
    "what_if_threat": {**THREAT_FIELDS, "id": ("id", REQ)},
    "preview_request": {
        "start": ("point", OPT),
        "goal": ("point", OPT),
        "threats": ("whatif_threats", DEF),
        "delta": ("delta", OPT),
        "step": ("length", OPT),
        "tolerance": ("length", OPT),
        "max_iter": ("iterations", OPT),
        "geojson": ("bool", DEF),
    },
    "direction": {
        "unit": ("id", REQ),
        "seq": ("count", OPT),
        "status": ("status", REQ),
        "vector": ("point", REQ),
        "heading_deg": ("angle", OPT),
        "distance_to_goal": ("nonneg", OPT),
        "threat_level": ("nonneg", DEF),
        "lookahead": ("points", DEF),
        "reason": ("text", DEF),
        "deliberating": ("bool", DEF),
        "planner": ("id", OPT),
        "true_bearing_deg": ("angle", OPT),
        "lookahead_geo": ("latlons", DEF),
        "reach_m": ("nonneg", OPT),
        "route": ("route", DEF),
        "progress": ("progress", DEF),
        "route_left_m": ("nonneg", OPT),
    },
    "error_reply": {"error": ("text", REQ), "field": ("text", DEF)},
    "planner_status": {
        "planner": ("id", REQ),
        "mission": ("id", REQ),
        "version": ("text", DEF),
        "uptime_s": ("nonneg", REQ),
        **{
            c: ("count", DEF)
            for c in (
                "units",
                "units_stale",
                "threats",
                "zones",
                "msgs_in",
                "msgs_out",
                "rejected",
                "deliberating",
                "overload",
                "units_owned",
                "pushes",
                "pushes_resent",
                "faults",
            )
        },
        "session": ("text", DEF),
        "origin": ("origin", OPT),
        "latency_p50_ms": ("nonneg", OPT),
        "latency_p99_ms": ("nonneg", OPT),
        "twins": ("texts", DEF),
        "terrain": ("terrain", OPT),
    },
    "event.rejected": {
        **EVENT_FIELDS,
        "key": ("text", REQ),
        "field": ("text", DEF),
        "reason": ("text", REQ),
        "truncated": ("bool", DEF),
        "suppressed": ("count", DEF),
    },
    "event.replan": {
        **EVENT_FIELDS,
        "units": ("ids", REQ),
        "reason": ("text", REQ),
        "changes": ("changes", DEF),
        "more": ("count", DEF),
        "more_units": ("count", DEF),
    },
    "event.trapped": {
        **EVENT_FIELDS,
        "unit": ("id", REQ),
        "position": ("point", REQ),
        "reason": ("text", DEF),
    },
    "event.arrived": {
        **EVENT_FIELDS,
        "unit": ("id", REQ),
        "position": ("point", REQ),
        "distance_to_goal": ("nonneg", DEF),
    },
}


def _payload(name: str, field: str, value: Any) -> tuple[bytes, str]:
    """The valid example of ``name`` with ``field`` set to ``value`` (or removed), and its path prefix."""
    if name == "what_if_threat":
        outer = copy.deepcopy(BASES["preview_request"])
        inner, prefix = outer["threats"][0], "$.threats[0]"
    else:
        outer = inner = copy.deepcopy(BASES[name])
        prefix = "$"
    if value is MISSING:
        inner.pop(field, None)
    else:
        inner[field] = value
    return json.dumps(outer, ensure_ascii=False).replace(
        repr(BIG).replace("e", "e+"), "1e999"
    ).encode(), prefix


def _bad_cases() -> Iterator[Any]:
    for name, fields in FIELDS.items():
        for field, (kind, how) in fields.items():
            for value, sub, reason in BAD[kind]:
                yield pytest.param(name, field, value, sub, reason, id=f"{name}.{field}={str(value)[:20]}")
            if how in (REQ, SHAPE_REQ):
                yield pytest.param(name, field, MISSING, "", "is required", id=f"{name}.{field}=missing")
            if how == SHAPE_REQ:
                yield pytest.param(name, field, None, "", "is required", id=f"{name}.{field}=null")
            elif how != OPT:
                yield pytest.param(name, field, None, "", "got null", id=f"{name}.{field}=null")


@pytest.mark.unit
@pytest.mark.parametrize(("name", "field", "value", "sub", "reason"), list(_bad_cases()))
def test_every_bad_value_of_every_field_is_rejected_with_its_path(
    name: str, field: str, value: Any, sub: str, reason: str
) -> None:
    data, prefix = _payload(name, field, value)
    with pytest.raises(InputError) as e:
        DECODERS[name](data)
    assert e.value.path == f"{prefix}.{field}{sub}", str(e.value)
    # Optional fields say "expected array | null" or "a finite number or null"; the rest is the same.
    assert reason in e.value.reason.replace(" | null", "").replace(" or null", ""), str(e.value)
    assert str(e.value) == f"{e.value.path}: {e.value.reason}"


def _good_cases() -> Iterator[Any]:
    for name, fields in FIELDS.items():
        for field, (_, how) in fields.items():
            if how == OPT:
                yield pytest.param(name, field, None, id=f"{name}.{field}=null")
            if how not in (REQ, SHAPE_REQ):
                yield pytest.param(name, field, MISSING, id=f"{name}.{field}=missing")


@pytest.mark.unit
@pytest.mark.parametrize(("name", "field", "value"), list(_good_cases()))
def test_optional_fields_may_be_left_out(name: str, field: str, value: Any) -> None:
    data, _ = _payload(name, field, value)
    DECODERS[name](data)


@pytest.mark.unit
@pytest.mark.parametrize("name", list(FIELDS))
def test_the_table_covers_every_field_of_every_message(name: str) -> None:
    """A new field must join FIELDS (and so get its bad values tested) and must have a default."""
    info = msgspec.inspect.type_info(TYPES[name])
    assert isinstance(info, msgspec.inspect.StructType)
    actual = {}
    for f in info.fields:
        nullable = isinstance(f.type, msgspec.inspect.UnionType) and f.type.includes_none
        actual[f.name] = REQ if f.required else OPT if nullable else DEF
    assert actual == {f: OPT if how == SHAPE_REQ else how for f, (_, how) in FIELDS[name].items()}


@pytest.mark.unit
@pytest.mark.parametrize("name", list(DECODERS))
def test_examples_decode_and_round_trip(name: str) -> None:
    payload = BASES["preview_request"] if name == "what_if_threat" else BASES[name]
    msg = DECODERS[name](json.dumps(payload).encode())
    assert msgspec.json.decode(m.encode(msg)) == payload


@pytest.mark.unit
def test_boundary_values_are_accepted() -> None:
    m.decode_unit_state(
        b'{"position":[-1e9,1e9],"heading_deg":-360,"speed_mps":0,"seq":9007199254740991,"t":0}'
    )
    m.decode_threat(
        b'{"position":[0,0],"facing_deg":360,"sigma_range":1e-3,"sigma_lateral":1e3,"skew":1000,"weight":0}'
    )
    m.decode_direction(
        b'{"unit":"' + b"u" * 64 + b'","status":"no_goal","vector":[0,0],"reason":"' + b"r" * 1024 + b'"}'
    )
