"""The map and the TAK bridge against the planner's origin: another than the planner's is refused (issue 22's trap).

Both only turn the planner's metres into lat/lon and back, so an ``--origin``
other than the planner's would draw (or send to ATAK) every position off by
the distance between the two.  Asked at start; a planner that has not
answered yet cannot be checked, and the client says so and runs; with a
planner in plain metres, the client's origin says where those metres lie.
"""

from __future__ import annotations

import subprocess
import sys
import time
import uuid

import pytest

from tests.conftest import ROOT, run_pfp
from tests.zenoh_util import free_port, planner_process

pytestmark = pytest.mark.proc

PLANNER = "58.4105,15.6213"
ELSEWHERE = "58.4205,15.6213"  # 1.1 km north


def _one_line_exit_2(r: subprocess.CompletedProcess[str]) -> str:
    """The error: one line, the last (the bridge names its mission and links first), exit 2, no traceback."""
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert "Traceback" not in r.stderr and sum("--origin" in x for x in lines) == 1, r.stderr
    return lines[-1]


def _client(kind: str, endpoint: str, mission: str, origin: str) -> list[str]:
    if kind == "map":
        return [
            kind,
            "--http",
            f"127.0.0.1:{free_port()}",
            "--origin",
            origin,
            "--connect",
            endpoint,
            "--mission",
            mission,
        ]
    cot = f"tcp://127.0.0.1:{free_port()}"  # nobody listens: the check comes before any link
    return [
        kind,
        "--origin",
        origin,
        "--cot-url",
        cot,
        "--state-dir",
        "none",
        "--connect",
        endpoint,
        "--mission",
        mission,
    ]


@pytest.mark.parametrize("kind", ["map", "tak"])
def test_another_origin_than_the_planners_is_one_line_exit_2_naming_both(kind):
    mission = "o" + uuid.uuid4().hex[:10]
    with planner_process("--origin", PLANNER, "--state-dir", "none", mission=mission) as (
        endpoint,
        _proc,
    ):
        line = _one_line_exit_2(run_pfp(*_client(kind, endpoint, mission, ELSEWHERE), timeout=60))
    assert "--origin" in line and ELSEWHERE in line and PLANNER in line and "(1,114 m away)" in line, line


def test_a_map_with_an_origin_runs_against_a_planner_in_plain_metres_and_says_whose_origin_it_is():
    """A planner without an origin works in plain metres; the map's origin then says where they lie on the earth."""
    mission = "o" + uuid.uuid4().hex[:10]
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, _proc):
        args = _client("map", endpoint, mission, PLANNER)
        proc = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", *args], cwd=ROOT, stderr=subprocess.PIPE, text=True
        )
        try:
            seen = []
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not any("origin" in x for x in seen):
                seen.append(proc.stderr.readline())
            assert any(
                "has no origin: its metres are taken from --origin 58.4105,15.6213" in x for x in seen
            ), seen
            assert proc.poll() is None  # and it runs
        finally:
            proc.terminate()
            proc.wait(timeout=30)
        assert proc.returncode == 0
