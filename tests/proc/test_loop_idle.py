"""The planner's loop does not poll: idle, the planner process spends almost no CPU, and it still answers at once.

Before, the loop looked at the state ring every 0.3-1 ms: 3.6 % of a core idle
(measured, the same machine and load as the 0.7 % after).  CPU seconds, not
wall time, so a loaded machine does not make this fail; the bound is 2 %.
"""

from __future__ import annotations

import os
import time

import pytest

from pfp_service.wire import keys
from tests.zenoh_util import Inbox, client, planner_process, put_json

pytestmark = pytest.mark.proc

IDLE_S = 6.0


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="reads /proc")
def test_an_idle_planner_spends_under_2_percent_and_answers_the_first_state_at_once():
    mission = "idle" + str(os.getpid())
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, proc), client(endpoint) as s:
        time.sleep(2.0)  # past start-up
        c0, t0 = _cpu_s(proc.pid), time.monotonic()
        time.sleep(IDLE_S)
        share = (_cpu_s(proc.pid) - c0) / (time.monotonic() - t0)
        assert share < 0.02, f"idle planner used {100 * share:.1f} % of a core"
        inbox = Inbox(s, keys.unit_direction(mission, "u1"))
        time.sleep(0.3)
        t_put = time.monotonic()
        put_json(s, keys.shard_state(mission, "u1"), {"position": [0.0, 0.0], "seq": 1})
        inbox.get(
            timeout=5.0
        )  # the waiter woke the loop: answered (a poll-free loop that never woke would not)
        assert time.monotonic() - t_put < 5.0


@pytest.mark.skipif(not hasattr(os, "SCHED_BATCH"), reason="SCHED_BATCH and /proc are Linux's")
def test_a_serving_planner_traces_its_loop_and_zenohs_threads_do_not_preempt_it(tmp_path, monkeypatch):
    """``loop_trace`` (here ``PFP_LOOP_TRACE``) gets a JSON line a second; Zenoh's tx/rx run under SCHED_BATCH."""
    import json

    trace = tmp_path / "loop.jsonl"
    monkeypatch.setenv("PFP_LOOP_TRACE", str(trace))
    mission = "trace" + str(os.getpid())
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, proc), client(endpoint) as s:
        inbox = Inbox(s, keys.unit_direction(mission, "u1"))
        time.sleep(0.3)
        for i in range(30):  # 3 s of one unit at 10 Hz
            put_json(s, keys.shard_state(mission, "u1"), {"position": [float(i), 0.0], "seq": i})
            time.sleep(0.1)
        inbox.get(timeout=5.0)
        policies = {}
        for tid in os.listdir(f"/proc/{proc.pid}/task"):
            with open(f"/proc/{proc.pid}/task/{tid}/comm") as f:
                name = f.read().strip()
            if name.split("-")[0] in ("rx", "tx"):
                policies[name] = os.sched_getscheduler(int(tid))
    assert policies and all(p == os.SCHED_BATCH for p in policies.values()), policies
    lines = [json.loads(ln) for ln in trace.read_text().splitlines()]
    assert sum(ln["states"] for ln in lines) >= 10, lines
    assert all(
        {"ticks", "apply_ms", "wall_max_ms", "loop_preempted", "gc"} <= ln.keys()
        for ln in lines
        if ln["states"]
    )
