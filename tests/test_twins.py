"""Two planners on one mission under one id (the default) see each other through their Zenoh sessions.

Both hold the same ``alive/planner/planner`` token, so liveliness cannot tell
them apart; each status names its session.  The bar: each reports the other
as a ``conflict`` within 5 s, and ``pfp status`` lists both.
"""

from __future__ import annotations

import json
import time
import uuid

import pytest

from pfp_service.wire import keys
from tests.conftest import run_pfp
from tests.test_delivery import _pfp, _text
from tests.zenoh_util import Inbox, client, planner_process, wait_for_planner

pytestmark = pytest.mark.multi


def test_a_second_planner_with_the_default_id_is_a_conflict_for_both_within_5s_and_status_lists_both():
    mission = "w" + uuid.uuid4().hex[:8]
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, _first), client(endpoint) as s:
        conflicts = Inbox(s, keys.event(mission, "conflict"))
        with _pfp(
            "serve", "--mode", "client", "--connect", endpoint, "--mission", mission, "--state-dir", "none"
        ) as (_second, log):
            ready = time.monotonic() + 120
            while "planner ready" not in _text(log):
                assert time.monotonic() < ready, _text(log)
                time.sleep(0.05)
            t_ready = time.monotonic()
            others: set[str] = set()
            while len(others) < 2:
                ev = conflicts.get(timeout=max(t_ready + 5.0 - time.monotonic(), 0.01))
                assert ev["planner"] == "planner"
                others.add(ev["other"])  # each names the other's session: two distinct names
            print(f"both conflicts {time.monotonic() - t_ready:.2f} s after the second was ready")
            assert all(o.startswith("planner-") for o in others)
            wait_for_planner(endpoint, mission)
            r = run_pfp("status", "--connect", endpoint, "--mission", mission, "--json", timeout=60)
            assert r.returncode == 0, r.stderr
            assert [w["planner"] for w in json.loads(r.stdout)] == ["planner", "planner"]
            r = run_pfp("status", "--connect", endpoint, "--mission", mission, timeout=60)
            rows = [line for line in r.stdout.splitlines() if line.startswith("planner (")]
            assert len(rows) == 2, r.stdout  # told apart by session
            r = run_pfp("health", "--connect", endpoint, "--mission", mission, timeout=60)
            assert r.stdout.count("planner ok") == 2, r.stdout


def test_twins_under_cluster_cannot_share_by_id_and_say_so_within_5s():
    """``--cluster`` shares units by planner id: two planners under one id would both own every unit."""
    mission = "w" + uuid.uuid4().hex[:8]
    flags = ("--state-dir", "none", "--cluster")
    with planner_process(*flags, mission=mission) as (endpoint, _first), client(endpoint) as s:
        conflicts = Inbox(s, keys.event(mission, "conflict"))
        with _pfp("serve", "--mode", "client", "--connect", endpoint, "--mission", mission, *flags) as (
            _p,
            log,
        ):
            ready = time.monotonic() + 120
            while "planner ready" not in _text(log):
                assert time.monotonic() < ready, _text(log)
                time.sleep(0.05)
            t_ready = time.monotonic()
            others: set[str] = set()
            while len(others) < 2:
                ev = conflicts.get(timeout=max(t_ready + 5.0 - time.monotonic(), 0.01))
                assert "--planner-id" in ev["reason"], ev
                others.add(ev["other"])
