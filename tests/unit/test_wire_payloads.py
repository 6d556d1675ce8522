"""Wire messages as whole payloads: the root's errors, the size limit before parsing, Zenoh's buffers."""

from __future__ import annotations

import json

import pytest

from pfp_service.errors import InputError
from pfp_service.wire import messages as m
from tests.unit.test_wire_messages import BASES


@pytest.mark.unit
@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"", "empty payload"),
        (b"{", "malformed JSON"),
        (b'{"position":[NaN,0]}', "malformed JSON"),
        (b'{"position":[Infinity,0]}', "malformed JSON"),
        (b"\xff\xfe", "malformed JSON"),
        (b"[1,2]", "expected object, got array"),
        (b"null", "expected object, got null"),
        (b'"hello"', "expected object, got str"),
    ],
)
def test_whole_payload_errors_have_the_root_path(data: bytes, reason: str) -> None:
    with pytest.raises(InputError) as e:
        m.decode_unit_state(data)
    assert e.value.path == "$"
    assert reason in e.value.reason


@pytest.mark.unit
def test_payload_size_is_limited_before_parsing() -> None:
    pad = b" " * m.MAX_PAYLOAD_BYTES
    ok = b'{"position":[1,2]}'
    m.decode_unit_state(ok + pad[: m.MAX_PAYLOAD_BYTES - len(ok)])
    with pytest.raises(InputError) as e:
        m.decode_unit_state(ok + pad)
    assert (e.value.path, e.value.reason) == (
        "$",
        f"payload of {m.MAX_PAYLOAD_BYTES + len(ok)} bytes exceeds the limit of {m.MAX_PAYLOAD_BYTES}",
    )


@pytest.mark.unit
def test_the_largest_legitimate_preview_request_fits() -> None:
    threat = {**BASES["what_if_threat"], "facing_deg": -123.456789, "sigma_range": 123.456789}
    many = [{**threat, "id": "t" * 60 + f"{i:04d}", "position": [-1e8 / 3, 1e8 / 7]} for i in range(256)]
    data = json.dumps({**BASES["preview_request"], "threats": many}).encode()
    assert len(data) < m.MAX_PAYLOAD_BYTES
    assert len(m.decode_preview_request(data).threats) == 256


@pytest.mark.unit
def test_decoders_accept_zenoh_style_buffers() -> None:
    data = json.dumps(BASES["unit_state"]).encode()
    assert m.decode_unit_state(bytearray(data)) == m.decode_unit_state(memoryview(data))
