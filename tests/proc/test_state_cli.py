"""``pfp state list|clear``: a mission's durable state shown and removed, as a user runs it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from pfp_service.node.store import Store
from pfp_service.wire import Goal, ThreatUpdate
from pfp_service.world.world import GoalSet, ThreatPut
from tests.zenoh_util import ROOT, free_port, wait_for_planner

pytestmark = pytest.mark.proc

T = dict(facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7, skew=2.0)


def _pfp(home: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PFP_")}
    env["XDG_STATE_HOME"] = str(home)
    return subprocess.run(
        [sys.executable, "-m", "pfp_service", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        env=env,
    )


def _state(home: Path, mission: str, goals: int) -> Path:
    d = home / "pfp" / mission
    store = Store(d)
    batch = [ThreatPut("e1", ThreatUpdate(position=(4, 6), **T))]
    batch += [GoalSet(f"u{i}", Goal(position=(10, 10))) for i in range(goals)]
    store.commit_inputs(batch, 0.0, None)
    store.close()
    return d


def test_list_shows_every_mission_and_clear_removes_one(tmp_path):
    _state(tmp_path, "alpha", 3)
    beta = _state(tmp_path, "beta", 57)
    r = _pfp(tmp_path, "state", "list", "--json")
    assert r.returncode == 0, r.stderr
    rows = {row["mission"]: row for row in json.loads(r.stdout)}
    assert set(rows) == {"alpha", "beta"}
    assert (rows["beta"]["threats"], rows["beta"]["goals"], rows["beta"]["planner_running"]) == (1, 57, False)
    assert rows["beta"]["path"] == str(beta)
    human = _pfp(tmp_path, "state", "list").stdout
    assert "alpha" in human and "beta" in human and str(beta) in human

    (beta / "tak-tombstones.json").write_text("{}")  # the TAK bridge's durable state, the same mission's
    r = _pfp(tmp_path, "state", "clear", "--mission", "beta")
    assert r.returncode == 0, r.stderr
    assert "cleared mission beta" in r.stdout and not beta.exists()
    again = _pfp(tmp_path, "state", "clear", "--mission", "beta")
    assert again.returncode == 0 and "nothing to clear" in again.stdout
    rows = json.loads(_pfp(tmp_path, "state", "list", "--json").stdout)
    assert [row["mission"] for row in rows] == ["alpha"]
    one = json.loads(_pfp(tmp_path, "state", "list", "--mission", "alpha", "--json").stdout)
    assert [row["goals"] for row in one] == [3]


def test_clear_refuses_while_a_planner_runs_on_the_state_then_clears_once_it_stopped(tmp_path):
    mission = "c" + uuid.uuid4().hex[:8]
    d = _state(tmp_path, mission, 2)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {**os.environ, "XDG_STATE_HOME": str(tmp_path), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--listen", endpoint, "--mission", mission],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        wait_for_planner(endpoint, mission)
        listed = json.loads(_pfp(tmp_path, "state", "list", "--mission", mission, "--json").stdout)
        assert listed[0]["planner_running"] is True and listed[0]["goals"] == 2
        r = _pfp(tmp_path, "state", "clear", "--mission", mission)
        assert r.returncode == 2
        (line,) = r.stderr.strip().splitlines()
        assert mission in line and "planner is running" in line and str(d) in line
        assert (d / "state.sqlite3").exists()
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    r = _pfp(tmp_path, "state", "clear", "--mission", mission)
    assert r.returncode == 0, r.stderr
    assert not d.exists()


@pytest.mark.parametrize(
    "args, names",
    [
        (("state", "clear", "--mission", "no spaces"), "--mission"),
        (("state", "list", "--state-dir", "none"), "--state-dir"),
        (("state", "list", "--bogus"), "--bogus"),
        (("state", "frobnicate"), "frobnicate"),
    ],
)
def test_bad_flags_are_one_line_and_exit_2(tmp_path, args, names):
    r = _pfp(tmp_path, *args)
    assert r.returncode == 2
    (line,) = r.stderr.strip().splitlines()
    assert names in line and "Traceback" not in r.stderr
