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
from tests.unit.test_delivery import _pfp, _text
from tests.zenoh_util import Inbox, client, planner_process, wait_for_planner

pytestmark = pytest.mark.multi


@pytest.mark.alone
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
            assert r.returncode == 1 and "WARNING: twin planner" in r.stderr, (r.returncode, r.stderr)
            conflict = [ln for ln in _text(log).splitlines() if "conflict" in ln]
            assert conflict and all("WARNING" in ln for ln in conflict), _text(log)


def _health(endpoint: str, mission: str):
    return run_pfp("health", "--connect", endpoint, "--mission", mission, timeout=60)


def test_two_planner_ids_without_cluster_are_twins_a_warning_in_log_status_and_health_until_one_goes():
    """Two ids, no ``--cluster``: both answer every unit (a vehicle overshot its goal); operators are told."""
    mission = "w" + uuid.uuid4().hex[:8]
    with planner_process("--state-dir", "none", "--planner-id", "alpha", mission=mission) as (
        endpoint,
        first,
    ):
        assert _health(endpoint, mission).returncode == 0  # alone: healthy
        second = ("serve", "--mode", "client", "--connect", endpoint, "--mission", mission)
        with _pfp(*second, "--state-dir", "none", "--planner-id", "bravo") as (_p, log):
            deadline = time.monotonic() + 120
            while "planner ready" not in _text(log):
                assert time.monotonic() < deadline, _text(log)
                time.sleep(0.05)
            while "conflict" not in _text(log):  # bravo hears alpha's token at once (history)
                assert time.monotonic() < deadline, _text(log)
                time.sleep(0.05)
            line = next(ln for ln in _text(log).splitlines() if "conflict" in ln)
            assert "WARNING" in line and "alpha" in line, line
            r = _health(endpoint, mission)
            assert r.returncode == 1, (r.stdout, r.stderr)
            warned = [ln for ln in r.stderr.splitlines() if "WARNING: twin planner" in ln]
            assert len(warned) == 2, r.stderr  # each names the other
            r = run_pfp("status", "--connect", endpoint, "--mission", mission, "--json", timeout=60)
            assert "WARNING: twin planner" in r.stderr, r.stderr
            json.loads(r.stdout)  # stdout stays JSON
            r = run_pfp("status", "--connect", endpoint, "--mission", mission, timeout=60)
            assert "WARNING: twin planner: bravo also answer(s) the units of planner alpha" in r.stderr, (
                r.stderr
            )
        deadline = time.monotonic() + 30  # bravo gone: its token's DELETE clears alpha's twin
        while (r := _health(endpoint, mission)).returncode != 0:
            assert time.monotonic() < deadline, r.stderr
            time.sleep(0.2)
        assert "WARNING" not in r.stderr
        assert first.poll() is None


@pytest.mark.alone
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
