"""With a mission origin, no human-facing output shows only metres (issue 25): ``pfp plan`` (and its
``--coords``), and one planner with its clients: ``pfp serve``'s human log, ``pfp inject``,
``pfp fleet`` and ``pfp status``, each a subprocess as a user runs it."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from tests.conftest import EXAMPLES, ROOT, run_pfp
from tests.zenoh_util import free_port, wait_for_planner

pytestmark = pytest.mark.proc

ORIGIN = "58.4105,15.6213"
LATLON = re.compile(r"\d+\.\d{5}[NS] \d+\.\d{5}[EW] \((the origin|[\d.]+ m [EW], [\d.]+ m [NS])\)")
MGRS = re.compile(r"\d{1,2}[C-X][A-Z]{2} \d{5} \d{5} \(")
# a position in bare metres, as these outputs printed before: "(801.428, 999.255)"
BARE = re.compile(r"\(-?\d+(\.\d+)?, -?\d+(\.\d+)?\)")


def _no_bare_metres(text: str, what: str) -> None:
    bare = [line for line in text.splitlines() if BARE.search(line)]
    assert not bare, f"{what} shows positions in metres only:\n" + "\n".join(bare[:10])


def test_plan_summary_in_latlon_and_mgrs():
    r = run_pfp("plan", str(EXAMPLES / "geo-simple.yaml"))
    assert r.returncode == 0, r.stderr
    for word in ("start", "goal", "end"):
        line = next(line for line in r.stdout.splitlines() if line.strip().startswith(word))
        assert LATLON.search(line), line
    assert "58.41050N 15.62130E (the origin)" in r.stdout  # the start is the origin
    _no_bare_metres(r.stdout, "pfp plan")
    r = run_pfp("plan", str(EXAMPLES / "geo-simple.yaml"), "--coords", "mgrs")
    assert r.returncode == 0, r.stderr
    assert "33VWE 36303 74581 (the origin)" in r.stdout, r.stdout
    # without an origin, metres; asking for lat/lon there is a flag error naming the file
    r = run_pfp("plan", str(EXAMPLES / "paper-simple.yaml"), "--coords", "latlon")
    assert r.returncode == 2 and "--coords" in r.stderr and "paper-simple.yaml" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def _team(tmp_path):
    text = (EXAMPLES / "demo-team.yaml").read_text()
    team = tmp_path / "team.yaml"
    team.write_text(f"origin: {{lat: {ORIGIN.split(',')[0]}, lon: {ORIGIN.split(',')[1]}}}\n" + text)
    return team


def _script(tmp_path):
    lat, lon = ORIGIN.split(",")
    script = tmp_path / "inject.yaml"
    script.write_text(
        f"name: latlon-out\norigin: {{lat: {lat}, lon: {lon}}}\nduration_s: 60\ntimeline:\n"
        "  - {do: add_threat, threat: e1, position: [20, 18], facing_deg: 250, sigma_range: 5, "
        "sigma_lateral: 3.5, skew: 2}\n"
        "  - {do: add_threat, threat: e2, position: {lat: 58.4108, lon: 15.6219}, sigma_range: 4, sigma_lateral: 3}\n"
        "  - {do: move_threat, threat: e2, position: [44, 12]}\n"
    )
    return script


def test_serve_inject_fleet_and_status_show_latlon(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mission = "latlon-out"
    log_path = tmp_path / "serve.log"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    with log_path.open("w") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", "serve", "--listen", endpoint, "--mission", mission,
             "--origin", ORIGIN, "--state-dir", "none"],
            cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        try:
            wait_for_planner(endpoint, mission)
            common = ("--connect", endpoint, "--mission", mission)
            inject = run_pfp("inject", str(_script(tmp_path)), *common, "--speed-up", "10", timeout=180)
            assert inject.returncode == 0, inject.stdout + inject.stderr
            fleet = run_pfp(
                "fleet", "--team", str(_team(tmp_path)), *common, "--speed-up", "20", "--until-arrived",
                "--progress-s", "60", timeout=240,
            )  # fmt: skip
            assert fleet.returncode == 0, fleet.stdout + fleet.stderr
            status = run_pfp("status", *common, "--timeout", "5", timeout=60)
            assert status.returncode == 0, status.stdout + status.stderr
            status_mgrs = run_pfp("status", *common, "--timeout", "5", "--coords", "mgrs", timeout=60)
            assert status_mgrs.returncode == 0, status_mgrs.stderr
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    served = log_path.read_text()

    # pfp inject: every action with a position
    actions = [line for line in inject.stdout.splitlines() if re.search(r"(add|move) threat", line)]
    assert len(actions) >= 3 and all(LATLON.search(line) for line in actions), inject.stdout
    _no_bare_metres(inject.stdout, "pfp inject")

    # pfp fleet: goals, arrivals and the summary's positions, units in natural order
    said = [line for line in fleet.stdout.splitlines() if line.startswith("t=")]
    goals = [line for line in said if " goal " in line]
    arrived = [line for line in said if " arrived at " in line]
    assert len(goals) == 6 and all(LATLON.search(line) for line in goals), fleet.stdout
    assert len(arrived) == 6 and all(LATLON.search(line) for line in arrived), fleet.stdout
    table = fleet.stdout[fleet.stdout.index("unit  kind") :].splitlines()[1:7]
    assert [row.split()[0] for row in table] == ["m1", "m2", "m3", "r1", "r2", "r3"]
    assert all(LATLON.search(row) for row in table), table
    _no_bare_metres(fleet.stdout, "pfp fleet")

    # pfp status: the units' and threats' positions
    rows = [line for line in status.stdout.splitlines() if re.match(r"(m|r)\d |e\d ", line)]
    assert len(rows) == 8 and all(LATLON.search(row) for row in rows), status.stdout
    _no_bare_metres(status.stdout, "pfp status")
    assert len(MGRS.findall(status_mgrs.stdout)) == 8, status_mgrs.stdout

    # pfp serve: the human log's goals, threats and unit events
    changes = [
        line for line in served.splitlines() if re.search(r"goal of \S+ set to|threat \S+ put at", line)
    ]
    assert len(changes) >= 6 + 3 and all(LATLON.search(line) for line in changes), served
    arrivals = [line for line in served.splitlines() if " arrived " in line]
    assert arrivals and all(LATLON.search(line) for line in arrivals), served
    assert "ThreatChange(" not in served
    _no_bare_metres(served, "pfp serve's log")
