"""Hostile input at the wire boundary: every decoder and ``keys.parse`` raise ``InputError`` and nothing else.

The payloads are ``pfp bench fuzz``'s own generator (seeded, printed on
failure) plus hypothesis over raw bytes and text.
"""

from __future__ import annotations

import json
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.fuzz import CATEGORIES, malformed
from pfp_service.errors import InputError
from pfp_service.wire import RejectedEvent, decode_event, encode, keys
from pfp_service.wire import messages as wm
from pfp_service.world.translate import decode_plan_result

pytestmark = pytest.mark.unit

DECODERS = [
    wm.decode_unit_state,
    wm.decode_goal,
    wm.decode_threat,
    wm.decode_preview_request,
    wm.decode_direction,
    wm.decode_planner_status,
    wm.decode_error_reply,
    wm.decode_event,
    decode_plan_result,
]


def _only_input_error(decode, data) -> None:
    try:
        decode(data)
    except InputError as exc:
        assert len(exc.reason) <= wm.TEXT_MAX_CHARS
        return
    # decode_preview_request accepts an empty body: the live preview


@pytest.mark.parametrize("decode", DECODERS, ids=lambda f: f.__name__)
def test_the_fuzz_generator_never_gets_past_a_decoder(decode):
    seed = 20261201
    rng = random.Random(seed)
    for i in range(600):
        category, payload, _odd = malformed(rng, "unit_state" if i % 2 else "preview")
        try:
            _only_input_error(decode, payload)
        except Exception as exc:  # pragma: no cover - the failure report
            pytest.fail(f"seed {seed} #{i} {category}: {type(exc).__name__}: {exc} on {payload[:80]!r}")


@settings(max_examples=300, deadline=None)
@given(data=st.binary(max_size=4096))
def test_random_bytes_raise_only_input_error(data):
    for decode in DECODERS:
        _only_input_error(decode, data)


@pytest.mark.parametrize(
    "payload, reason",
    [
        (b"[" * 100_000, "expected object, got array"),
        (b'{"position": ' + b"[" * 100_000, "nested too deeply|expected a finite number"),
        (b'{"position": [1, 2], "x": ' + b'{"a": ' * 30_000, "nested too deeply"),
        (b'{"position": [NaN, 1]}', "malformed JSON"),
        (b'{"position": [Infinity, 1]}', "malformed JSON"),
        (b'{"position": [1e999, 1]}', "expected a finite number"),
        (b'{"position": [1' + b"0" * 5000 + b", 1]}", "expected a finite number"),
        (b'{"position": [1, 2], "seq": ' + b"9" * 400 + b"}", "must be <="),
        (b"\xff\xfe{\x00", "malformed JSON"),
        (b'{"position": [1, 2], "kind": "\\ud800"}', "malformed JSON"),
        (b" " * (wm.MAX_PAYLOAD_BYTES + 1), "exceeds the limit"),
    ],
)
def test_hostile_payloads_are_named(payload, reason):
    with pytest.raises(InputError, match=reason):
        wm.decode_unit_state(payload)


def test_the_size_is_checked_before_decoding():
    """A megabyte of nesting is refused for its size, not parsed: the check comes first."""
    with pytest.raises(InputError, match="exceeds the limit") as info:
        wm.decode_unit_state(b"[" * (1 << 20))
    assert info.value.path == "$"


@settings(max_examples=300, deadline=None)
@given(key=st.text(max_size=400) | st.text(alphabet="/*$?#ab-_.é", max_size=300))
def test_keys_parse_takes_any_text(key):
    try:
        k = keys.parse(key)
    except InputError as exc:
        assert len(exc.reason) < 300
        return
    assert keys.TEMPLATES[k.kind].format(mission=k.mission, id=k.id) == key


def test_keys_parse_refuses_megabyte_keys_quickly_and_briefly():
    with pytest.raises(InputError, match=r"\(1000000 characters\) is longer than 256") as info:
        keys.parse("mumt/" + "a" * 999_995)
    assert len(str(info.value)) < 200


def test_rejected_events_fit_their_schema_and_say_they_were_cut():
    long_key = "mumt/m/unit/" + "x" * 10_000 + "/state"
    ev = RejectedEvent.of(long_key, InputError("$.position", "r" * 5000), planner="p", t=1.0)
    assert ev.truncated
    assert len(ev.key) == len(ev.reason) == wm.TEXT_MAX_CHARS
    assert ev.key.endswith("…") and ev.reason.endswith("…")
    back = decode_event(encode(ev))
    assert back == ev
    short = RejectedEvent.of("mumt/m/unit/u1/state", InputError("$", "empty payload"))
    assert not short.truncated and short.key == "mumt/m/unit/u1/state"


def test_error_replies_fit_their_schema():
    reply = wm.ErrorReply.of(InputError("$", "e" * 5000))
    assert len(reply.error) == wm.TEXT_MAX_CHARS
    assert wm.decode_error_reply(encode(reply)) == reply


def test_every_category_is_generated():
    rng = random.Random(1)
    seen = {malformed(rng, "goal").category for _ in range(3000)}
    assert seen == set(CATEGORIES)


def test_lat_lon_junk_is_refused_before_it_is_walked():
    """The lat/lon path walks the document in Python; hostile ones are refused by counting first."""
    origin = wm.Origin(lat=48.0, lon=11.0)
    junk = [{"lat": 48.001, "lon": 11.001}] * 8000
    with pytest.raises(InputError, match="more lat/lon positions than the 1"):
        wm.decode_unit_state(json.dumps({"position": [1, 2], "x": junk}).encode(), None, origin)
    nested = {"position": {"lat": 48.0, "lon": 11.0}, "x": [[[]] * 50] * 100}
    with pytest.raises(InputError, match="more JSON objects and arrays"):
        wm.decode_unit_state(json.dumps(nested).encode(), None, origin)
    threats = [
        {
            "id": f"t{i}",
            "position": {"lat": 48.0, "lon": 11.0 + i * 1e-5},
            "sigma_range": 1,
            "sigma_lateral": 1,
        }
        for i in range(300)
    ]
    with pytest.raises(InputError, match="more lat/lon positions than the 258"):
        wm.decode_preview_request(json.dumps({"threats": threats}).encode(), None, origin)
    with pytest.raises(InputError, match=r"\$\.threats: length must be <= 256"):  # within the count: typed
        wm.decode_preview_request(json.dumps({"threats": threats[:257]}).encode(), None, origin)
    # what a real message holds still decodes, unknown fields and all
    full = {"start": {"lat": 48.0, "lon": 11.0}, "goal": [5, 5], "threats": threats[:256], "future": [[1]]}
    req = wm.decode_preview_request(json.dumps(full).encode(), None, origin)
    assert len(req.threats) == wm.MAX_WHATIF_THREATS and req.start == pytest.approx((0.0, 0.0), abs=1e-6)
    state = wm.decode_unit_state(
        memoryview(b'{"position": {"lat": 48.0, "lon": 11.0}, "x": {"a": [1]}}'), None, origin
    )
    assert state.position == pytest.approx((0.0, 0.0), abs=1e-6)
