"""``pfp replay --mission M`` writes only to M: a record holding another mission's inputs is refused, and
what it puts goes to M's keys (a real replay into a real Zenoh session); a far-future log time, which
held the replay until signalled, is refused when the record is read."""

from __future__ import annotations

import json
import threading
import time

import pytest
from pfp_clients.record.mcapfile import MissionWriter, read_record
from pfp_clients.record.replay import replay, replay_inputs

from pfp_service.errors import InputError
from pfp_service.wire import keys
from tests.conftest import run_pfp

S = 1_000_000_000
T0 = 1_700_000_000 * S  # a recorder's wall clock in 2023


def _write(path, mission: str, extra: list[tuple[str, bytes | None, int]] = ()) -> None:
    with path.open("wb") as f:
        w = MissionWriter(f, mission, None, T0)
        w.put(keys.unit_goal(mission, "u1"), json.dumps({"position": [10, 10]}).encode(), T0 + S)
        w.put(keys.unit_state(mission, "u1"), json.dumps({"position": [0, 0], "seq": 1}).encode(), T0 + 2 * S)
        w.alive(keys.alive_unit(mission, "u1"), True, T0 + S)
        for key, data, t in extra:
            if data is None:
                w.delete(key, t)
            else:
                w.put(key, data, t)
        w.finish()


@pytest.mark.unit
def test_a_record_with_another_missions_inputs_is_refused(tmp_path):
    p = tmp_path / "r.mcap"
    _write(p, "m1", [("mumt/victim/unit/v1/goal", b'{"position": [1, 1]}', T0 + 3 * S)])
    rec = read_record(p)
    with pytest.raises(InputError) as got:
        replay_inputs(rec, "sandbox")
    assert "mumt/victim/unit/v1/goal" in got.value.reason and "'sandbox'" in got.value.reason
    _write(p, "m1", [(keys.threat("victim", "e1"), None, T0 + 3 * S)])  # a delete is a write too
    with pytest.raises(InputError, match="victim"):
        replay_inputs(read_record(p), "sandbox")


@pytest.mark.unit
def test_every_input_is_retargeted_onto_the_mission_given(tmp_path):
    p = tmp_path / "r.mcap"
    _write(p, "m1", [(keys.shard_state("m1", "u2"), b'{"position": [0, 0], "seq": 1}', T0 + 3 * S)])
    targets = [t for _e, _k, t in replay_inputs(read_record(p), "sandbox")]
    assert len(targets) == 3 and all(keys.parse(t).mission == "sandbox" for t in targets), targets


@pytest.mark.unit
def test_a_far_future_log_time_is_refused(tmp_path):
    p = tmp_path / "r.mcap"
    _write(p, "m1", [(keys.unit_state("m1", "u1"), b'{"position": [0, 0], "seq": 2}', 2**62)])
    with pytest.raises(InputError, match="in the future"):
        read_record(p)
    _write(p, "m1", [(keys.unit_state("m1", "u1"), b'{"position": [0, 0], "seq": 2}', T0 + 30 * 86_400 * S)])
    with pytest.raises(InputError, match=r"\(mcap_span_s\)"):
        read_record(p)


@pytest.mark.proc
def test_pfp_replay_refuses_a_foreign_key_in_one_line_before_connecting(tmp_path):
    p = tmp_path / "r.mcap"
    _write(p, "m1", [("mumt/victim/unit/v1/goal", b'{"position": [1, 1]}', T0 + 3 * S)])
    t0 = time.monotonic()
    r = run_pfp("replay", str(p), "--mission", "sandbox", "--connect", "tcp/127.0.0.1:9", timeout=60)
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "r.mcap" in lines[0] and "mumt/victim/unit/v1/goal" in lines[0], r.stderr
    assert time.monotonic() - t0 < 10


@pytest.mark.net
def test_a_replay_puts_nothing_outside_its_mission(tmp_path):
    """A real replay into a real session: every sample seen on ``mumt/**`` is on the mission given."""
    from tests.unit.test_delivery import _router
    from tests.zenoh_util import client, free_port

    p = tmp_path / "r.mcap"
    threat = b'{"position": [5, 5], "sigma_range": 2, "sigma_lateral": 1}'
    _write(p, "m1", [(keys.threat("m1", "e1"), threat, T0 + 3 * S)])
    rec = read_record(p)
    seen: list[str] = []
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = _router(endpoint)
    try:
        with client(endpoint) as watcher, client(endpoint) as writer:
            sub = watcher.declare_subscriber(f"{keys.PREFIX}/**", lambda s: seen.append(str(s.key_expr)))
            ack = b'{"planner": "test", "outcome": "applied"}'
            q = watcher.declare_queryable(  # acknowledge the writes, as a planner would
                f"{keys.PREFIX}/**",
                lambda query: (seen.append(str(query.key_expr)), query.reply(query.key_expr, ack)),
            )
            deadline = time.monotonic() + 5  # the queryable reaches the router: a probe is answered
            while not any(r.ok for r in writer.get("mumt/sandbox/probe", timeout=0.5)):
                assert time.monotonic() < deadline, "the acknowledging queryable never answered"
            seen.clear()
            result = replay(
                writer, rec, "sandbox", 100.0, threading.Event(), say=lambda _l: None, settle_s=0.2
            )
            assert result.inputs_sent == 3
            deadline = time.monotonic() + 5
            while len(set(seen)) < 3 and time.monotonic() < deadline:
                time.sleep(0.02)
            q.undeclare()
            sub.undeclare()
    finally:
        router.close()
    assert len(set(seen)) >= 3, seen
    assert all(keys.parse(k).mission == "sandbox" for k in seen), seen
