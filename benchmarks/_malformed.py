"""The malformed inputs ``pfp bench fuzz`` sends: one seeded generator, drawn by category.

Random bytes, truncated JSON, deep nesting, wrong types, NaN and Infinity, huge
numbers, out-of-range values, bad UTF-8, non-objects, impossible lat/lon
positions, megabyte payloads and valid payloads on keys with odd ids.  Also the
property tests' source (tests/unit/test_fuzz_wire.py).
"""

from __future__ import annotations

import json
import random
from collections.abc import Callable
from typing import Any, NamedTuple

ORIGIN = "48.0,11.0"  # 58 N is 1,100 km north of it: too far for any mission
PROBE_TIMEOUT_S = 5.0

# A valid message of each kind, the starting point of the structured mutations.
_VALID: dict[str, dict[str, Any]] = {
    "unit_state": {"position": [1.0, 2.0], "seq": 1, "kind": "manned", "speed_mps": 1.4, "heading_deg": 90},
    "goal": {"position": [10.0, 10.0], "step": 0.1},
    "threat": {"position": [5.0, 5.0], "facing_deg": 225, "sigma_range": 1.0, "sigma_lateral": 0.7},
    "preview": {"start": [0.0, 0.0], "goal": [10.0, 10.0], "max_iter": 100},
}
# A value of the wrong type for any field of any message.
_WRONG = ["abc", {"x": 1}, [[1, 2]], True, [], ["1", "2"], [1], [1, 2, 3], None]
_NON_FINITE = [b"NaN", b"Infinity", b"-Infinity", b"1e999", b"-1e999", b"nan", b"inf"]
_HUGE = [b"1" + b"0" * 400, b"-" + b"9" * 400, b"1e308", b"18446744073709551617", b"1e9000000"]
# Valid Zenoh key chunks that are not valid ids: too long, dots, spaces, non-ASCII.
_ODD_IDS = ["x" * 65, "L" * 20_000, "a.b", "a b", "ü", "日本", "a~b", "..", "%2F", "-" * 200, "a+b", "é" * 64]


class Input(NamedTuple):
    """One fuzz input: its category, the payload, and an odd id to put it under (None: a normal id)."""

    category: str
    payload: bytes
    odd_id: str | None = None


def _base(kind: str) -> dict[str, Any]:
    return json.loads(json.dumps(_VALID[kind]))


def _random_bytes(rng: random.Random, kind: str) -> bytes:
    data = rng.randbytes(rng.randint(1, 600))
    return data if data.strip() not in (b"", b"{}") else b"\x00"


def _truncated(rng: random.Random, kind: str) -> bytes:
    text = json.dumps(_base(kind)).encode()
    return text[: rng.randint(1, len(text) - 1)]


def _deep(rng: random.Random, kind: str) -> bytes:
    n = rng.choice([600, 5_000, 50_000, 120_000])
    field = next(iter(_VALID[kind]))
    opener = rng.choice([b"[", b'{"a":'])
    return b'{"' + field.encode() + b'": ' + opener * n


def _wrong_type(rng: random.Random, kind: str) -> bytes:
    msg = _base(kind)
    field = next(iter(msg))  # the one required field (for a preview: the start)
    if rng.random() < 0.5:
        field = rng.choice(list(msg))
    required = field == next(iter(msg)) and kind != "preview"  # a preview's start may be null
    wrong = [w for w in _WRONG if w is not None or required]
    msg[field] = rng.choice(wrong)
    return json.dumps(msg).encode()


def _splice(rng: random.Random, kind: str, tokens: list[bytes]) -> bytes:
    """The valid message with one number replaced by a raw token (which json.dumps cannot write)."""
    msg = _base(kind)
    field = rng.choice([f for f, v in msg.items() if isinstance(v, (int, float, list))])
    marker = "__TOKEN__"
    msg[field] = [marker, 1.0] if isinstance(msg[field], list) else marker
    return json.dumps(msg).encode().replace(b'"__TOKEN__"', rng.choice(tokens))


def _non_finite(rng: random.Random, kind: str) -> bytes:
    return _splice(rng, kind, _NON_FINITE)


def _huge_number(rng: random.Random, kind: str) -> bytes:
    return _splice(rng, kind, _HUGE)


def _out_of_range(rng: random.Random, kind: str) -> bytes:
    msg = _base(kind)
    table: dict[str, list[tuple[str, Any]]] = {
        "unit_state": [("speed_mps", -1), ("heading_deg", 1e6), ("seq", -5), ("position", [1e12, 0])],
        "goal": [("step", 0), ("step", -1), ("tolerance", -1), ("position", [0, -2e9])],
        "threat": [("sigma_range", 0), ("sigma_lateral", 1e-9), ("skew", 1e9), ("weight", -1)],
        "preview": [("max_iter", 0), ("max_iter", 10**12), ("step", -1), ("threats", [{"id": "a"}])],
    }
    field, value = rng.choice(table[kind])
    msg[field] = value
    return json.dumps(msg).encode()


def _bad_text(rng: random.Random, kind: str) -> bytes:
    # invalid UTF-8 where a value is read (msgspec skips unknown fields without checking their text)
    first = next(iter(_VALID[kind])).encode()
    return rng.choice(
        [
            b'{"' + first + b'": "\xff\xfe"}',
            b'{"position": [1, 2], "kind": "\\ud800"}',
            b"\xef\xbb\xbf" + json.dumps(_base(kind)).encode()[:-1],
            json.dumps(_base(kind)).encode("utf-16"),
            b'{"position": "\x00\x01\x02"}',
        ]
    )


def _not_object(rng: random.Random, kind: str) -> bytes:
    return rng.choice([b"[]", b"1", b'"x"', b"null", b"true", b"[1, 2]", b"-0", b'"' + b"a" * 5000 + b'"'])


def _oversize(rng: random.Random, kind: str) -> bytes:
    from pfp_service.wire import MAX_PAYLOAD_BYTES

    head, tail = b'{"position": [1, 2], "pad": "', b'"}'
    size = rng.choice([MAX_PAYLOAD_BYTES + 1, 300_000, 1 << 20])
    return head + b" " * (size - len(head) - len(tail)) + tail


def _lat_lon(rng: random.Random, kind: str) -> bytes:
    """Positions in degrees that no origin makes valid, or more of them than a message holds."""
    msg = _base(kind)
    field = next(iter(msg))  # position, or a preview's start
    bad = [{"lat": 91.0, "lon": 11.0}, {"lat": 48.0}, {"lon": "east"}, {"lat": 58.0, "lon": 11.0}]
    msg[field] = rng.choice(bad)
    if rng.random() < 0.3:
        msg["junk"] = [{"position": {"lat": 48.0, "lon": 11.0}}] * rng.choice([300, 3000])
    return json.dumps(msg).encode()


def _odd_id(rng: random.Random, kind: str) -> bytes:
    return json.dumps(_base(kind)).encode()  # valid: only the key is wrong


# The categories and how often each is drawn (megabyte payloads rarely: they cost the most).
CATEGORIES: dict[str, tuple[float, Callable[[random.Random, str], bytes]]] = {
    "random_bytes": (14, _random_bytes),
    "truncated": (12, _truncated),
    "deep_nesting": (8, _deep),
    "wrong_type": (14, _wrong_type),
    "non_finite": (10, _non_finite),
    "huge_number": (8, _huge_number),
    "out_of_range": (12, _out_of_range),
    "bad_text": (8, _bad_text),
    "not_object": (8, _not_object),
    "lat_lon": (6, _lat_lon),
    "oversize": (0.3, _oversize),
    "odd_id": (6, _odd_id),
}
_NAMES = list(CATEGORIES)
_WEIGHTS = [w for w, _ in CATEGORIES.values()]


def malformed(rng: random.Random, kind: str) -> Input:
    """One malformed input for messages of ``kind`` (``unit_state``, ``goal``, ``threat``, ``preview``)."""
    category = rng.choices(_NAMES, _WEIGHTS)[0]
    payload = CATEGORIES[category][1](rng, kind)
    return Input(category, payload, rng.choice(_ODD_IDS) if category == "odd_id" else None)
