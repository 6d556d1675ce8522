"""Old state ages out: units restored from durable state are stale until they report, and forgotten on the clock.

Issue 22 item 8, the way a user meets it: one ``pfp serve`` takes 57 goals
(and one unit reports, so its mission is fixed), it stops; the next ``pfp
serve --unit-stale-s 2 --unit-forget-s 3`` on the same state restores them,
and ``pfp health`` says they are stale from the start and gone 3 s later.
"""

from __future__ import annotations

import re
import time
import uuid

import pytest

from pfp_service.wire import decode_planner_status, keys
from tests.conftest import run_pfp
from tests.zenoh_util import Inbox, client, planner_process, put_json

pytestmark = pytest.mark.proc

GOALS = 57


def _status(s, mission: str):
    for r in s.get(keys.planner_statuses(mission), timeout=5.0):
        if r.ok is not None:
            return decode_planner_status(r.ok.payload.to_bytes())
    return None


def _until(what: str, check, timeout: float = 30.0):
    deadline = time.monotonic() + timeout
    while True:
        got = check()
        if got:
            return got
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def test_restored_units_that_never_report_are_stale_at_once_and_forgotten_after_unit_forget_s(tmp_path):
    mission = "m" + uuid.uuid4().hex[:8]
    state = str(tmp_path / "state")
    with planner_process("--state-dir", state, mission=mission) as (endpoint, _proc), client(endpoint) as s:
        for k in range(GOALS):
            put_json(s, keys.unit_goal(mission, f"old{k}"), {"position": [10.0 + k, 10.0]})
        put_json(s, keys.unit_state(mission, "old0"), {"position": [0.0, 0.0], "seq": 1})  # a mission fixed
        _until("the goals", lambda: (st := _status(s, mission)) is not None and st.units == GOALS)
    with planner_process(
        "--state-dir", state, "--unit-stale-s", "2", "--unit-forget-s", "3", mission=mission
    ) as (endpoint, _proc):
        with client(endpoint) as s:
            forgotten = Inbox(s, keys.event(mission, "forgotten"))
            first = _until("a status", lambda: _status(s, mission))
            assert first.units == first.units_stale == GOALS, first  # stale from the start, not after 2 s
            # forgotten unit_forget_s after the restore, on the planner's own clock (stale_s counts from it)
            waits = [forgotten.get(timeout=30)["stale_s"] for _ in range(GOALS)]
            assert min(waits) >= 3.0 and max(waits) <= 3.0 + 0.5, waits
        health = run_pfp("health", "--connect", endpoint, "--mission", mission, timeout=60)
        assert health.returncode == 0 and re.search(r" 0 units \(0 stale\)", health.stdout), health.stdout
        # and they are gone from the durable state too: a third start restores nothing
    with planner_process("--state-dir", state, mission=mission) as (endpoint, _proc), client(endpoint) as s:
        st = _until("a status", lambda: _status(s, mission))
        assert st.units == 0, st
