"""Wire messages against mission bounds and across versions: bounded positions, older and newer decoders,
unknown fields and event kinds, and the contract's fixed values (split from ``test_wire_messages``)."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
import typing
from typing import Any

import msgspec
import pytest

from pfp_service.errors import InputError
from pfp_service.wire import messages as m
from pfp_service.world import translate
from tests.unit.test_wire_messages import BASES, DECODERS, _payload

# -- mission bounds ---------------------------------------------------------------
BOUNDS = ((0.0, 0.0), (10.0, 20.0))


@pytest.mark.unit
@pytest.mark.parametrize("pos", [[0, 0], [10, 20], [5, 7.5], [0, 20]])
def test_positions_within_bounds_pass(pos: list[float]) -> None:
    body = json.dumps({"position": pos}).encode()
    m.decode_unit_state(body, BOUNDS)
    m.decode_goal(body, BOUNDS)


@pytest.mark.unit
@pytest.mark.parametrize("pos", [[-0.001, 5], [10.001, 5], [5, -1], [5, 20.5], [-100, 100]])
@pytest.mark.parametrize("name", ["unit_state", "goal", "threat"])
def test_positions_outside_bounds_are_rejected(pos: list[float], name: str) -> None:
    data, _ = _payload(name, "position", pos)
    DECODERS[name](data)  # no bounds configured: fine
    with pytest.raises(InputError) as e:
        DECODERS[name](data, BOUNDS)  # type: ignore[call-arg]
    assert e.value.path == "$.position"
    assert "outside the mission bounds [[0, 0], [10, 20]]" in e.value.reason


@pytest.mark.unit
@pytest.mark.parametrize(
    ("change", "path"),
    [
        ({"start": [-1, 0]}, "$.start"),
        ({"goal": [11, 0]}, "$.goal"),
        ({"threats": [{**BASES["what_if_threat"], "position": [5, 25]}]}, "$.threats[0].position"),
    ],
)
def test_preview_request_positions_are_bounded(change: dict[str, Any], path: str) -> None:
    body = {"start": [1, 1], "goal": [9, 9], "threats": [{**BASES["what_if_threat"], "position": [5, 5]}]}
    m.decode_preview_request(json.dumps(body).encode(), BOUNDS)
    with pytest.raises(InputError) as e:
        m.decode_preview_request(json.dumps({**body, **change}).encode(), BOUNDS)
    assert e.value.path == path


@pytest.mark.unit
def test_messages_without_positions_pass_any_bounds() -> None:
    m.check_bounds(m.ErrorReply(error="x"), BOUNDS)
    m.check_bounds(m.PreviewRequest(), BOUNDS)


@pytest.mark.unit
@pytest.mark.parametrize("bad", [((0, 0), (0, 10)), ((5, 0), (1, 10)), ((0, 10), (10, 0))])
def test_inverted_bounds_are_a_configuration_error(bad: Any) -> None:
    with pytest.raises(ValueError, match="bounds"):
        m.check_bounds(m.Goal(position=(0, 0)), bad)


# -- evolution ----------------------------------------------------------------------
class UnitStateV2(m.UnitState, frozen=True, kw_only=True):
    """What a later contract might add: new fields, each with a default."""

    battery_pct: float = 100.0
    fix: dict[str, Any] = msgspec.field(default_factory=dict)


class WhatIfThreatV2(m.WhatIfThreat, frozen=True, kw_only=True):
    label: str = ""


class PreviewRequestV2(m.PreviewRequest, frozen=True, kw_only=True):
    threats: list[WhatIfThreatV2] = msgspec.field(default_factory=list)  # type: ignore[assignment]
    horizon_s: float | None = None


@pytest.mark.unit
def test_an_older_decoder_reads_a_newer_message() -> None:
    newer = UnitStateV2(position=(1.0, 2.0), seq=7, battery_pct=55.0, fix={"hdop": 0.9, "sats": [1, 2]})
    assert m.decode_unit_state(msgspec.json.encode(newer)) == m.UnitState(position=(1.0, 2.0), seq=7)
    nested = PreviewRequestV2(
        goal=(3.0, 4.0),
        horizon_s=30.0,
        threats=[
            WhatIfThreatV2(id="a", position=(1.0, 1.0), sigma_range=1.0, sigma_lateral=1.0, label="tank")
        ],
    )
    old = m.decode_preview_request(msgspec.json.encode(nested))
    assert old.goal == (3.0, 4.0)
    assert old.threats == [m.WhatIfThreat(id="a", position=(1.0, 1.0), sigma_range=1.0, sigma_lateral=1.0)]


@pytest.mark.unit
def test_a_newer_decoder_reads_an_older_message() -> None:
    old = m.encode(m.UnitState(position=(1.0, 2.0)))
    assert msgspec.json.decode(old, type=UnitStateV2).battery_pct == 100.0


@pytest.mark.unit
@pytest.mark.parametrize("name", list(DECODERS))
def test_unknown_fields_are_ignored_everywhere(name: str) -> None:
    payload = copy.deepcopy(BASES["preview_request"] if name == "what_if_threat" else BASES[name])
    payload["x_future"] = {"nested": [1, None, "a"]}
    if name in ("preview_request", "what_if_threat"):
        payload["threats"][0]["x_future"] = 1
    DECODERS[name](json.dumps(payload).encode())


@pytest.mark.unit
def test_an_unknown_event_kind_names_the_known_ones() -> None:
    with pytest.raises(InputError) as e:
        m.decode_event(b'{"kind":"teleported","unit":"u1"}')
    assert e.value.path == "$.kind"
    assert "rejected, replan, trapped, arrived" in e.value.reason


@pytest.mark.unit
def test_event_kinds_match_the_union() -> None:
    tags = set()
    for t in typing.get_args(m.AnyEvent):
        info = msgspec.inspect.type_info(t)
        assert isinstance(info, msgspec.inspect.StructType)
        tags.add(info.tag)
    assert tags == set(m.EVENT_KINDS)


# -- helpers the daemon uses ----------------------------------------------------------
@pytest.mark.unit
def test_threat_update_converts_to_the_core_threat() -> None:
    from pfp_service.core.threat import Threat

    upd = m.decode_threat(json.dumps(BASES["threat"]).encode())
    assert translate.threat(upd, "t9") == Threat.from_facing((4.0, 5.0), 180.0, 2.0, 1.0, 3.0, 1.0, "t9")


@pytest.mark.unit
def test_empty_preview_body_means_the_live_preview() -> None:
    assert m.decode_preview_request(None) == m.decode_preview_request(b"") == m.decode_preview_request(b"{}")
    assert not m.decode_preview_request(None).what_if
    assert m.decode_preview_request(b'{"max_iter": 10}').what_if


@pytest.mark.unit
def test_error_reply_and_rejected_event_carry_path_and_reason() -> None:
    with pytest.raises(InputError) as e:
        m.decode_threat(b'{"position":[0,0],"sigma_range":0,"sigma_lateral":1}')
    reply = m.ErrorReply.of(e.value)
    assert msgspec.json.decode(m.encode(reply)) == {"error": "must be >= 0.001", "field": "$.sigma_range"}
    ev = m.RejectedEvent.of("k/1", e.value, planner="p1", t=5.0)
    assert msgspec.json.decode(m.encode(ev)) == {
        "kind": "rejected",
        "planner": "p1",
        "t": 5.0,
        "key": "k/1",
        "field": "$.sigma_range",
        "reason": "must be >= 0.001",
        "truncated": False,
        "suppressed": 0,
    }
    assert m.decode_event(m.encode(ev)) == ev


@pytest.mark.unit
def test_direction_status_values_are_the_contract() -> None:
    # the contract only grows: "yielding" (dispersion's right of way, issue 33) came last
    assert [s.value for s in m.DirectionStatus] == [
        "en_route",
        "escaping",
        "arrived",
        "trapped",
        "no_goal",
        "yielding",
    ]


@pytest.mark.unit
def test_the_preview_reply_is_what_pfp_plan_json_prints(capsys: pytest.CaptureFixture[str]) -> None:
    from pathlib import Path

    from pfp_service.cli import main
    from pfp_service.core.plan import PlanResult

    scenario = Path(__file__).resolve().parents[2] / "examples" / "paper-simple.yaml"
    assert main(["plan", str(scenario), "--json"]) == 0
    out = capsys.readouterr().out
    result = translate.decode_plan_result(out.encode())
    assert isinstance(result, PlanResult)
    assert m.encode(result).decode() == out.strip()


@pytest.mark.proc
def test_wire_modules_import_without_zenoh_or_numpy() -> None:
    code = (
        "import sys, pfp_service.wire.messages, pfp_service.wire.keys, pfp_service.wire;"
        "bad = {'zenoh', 'numpy', 'numba'} & set(sys.modules); assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.unit
@pytest.mark.parametrize(
    ("body", "path"),
    [
        (b'{"position": [0, 0], "sigma_range": 1e-170, "sigma_lateral": 5}', "$.sigma_range"),
        (b'{"position": [0, 0], "sigma_range": 1e8, "sigma_lateral": 1}', "$.sigma_lateral"),
    ],
)
def test_wire_threat_rejects_degenerate_sigma(body, path):
    with pytest.raises(InputError) as exc:
        m.decode_threat(body)
    assert exc.value.path == path


@pytest.mark.unit
def test_wire_what_if_rejects_degenerate_sigma():
    body = b'{"threats": [{"id": "x", "position": [0, 0], "sigma_range": 1e-170, "sigma_lateral": 5}]}'
    with pytest.raises(InputError) as exc:
        m.decode_preview_request(body)
    assert exc.value.path == "$.threats[0].sigma_range"
