"""A team driven by ``pfp fleet`` and judged by ``pfp inject`` on a real planner: examples/team-scout*.yaml."""

from __future__ import annotations

import uuid

import pytest

from tests.conftest import EXAMPLES, run_pfp
from tests.unit.test_inject import _pfp, _wait_for_line
from tests.zenoh_util import planner_process

pytestmark = pytest.mark.proc


def test_the_scout_team_meets_its_expectations_with_a_threat_in_its_way():
    mission = "ts" + uuid.uuid4().hex[:8]
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, _):
        common = ("--connect", endpoint, "--mission", mission, "--speed-up", "10")
        judge = _pfp("inject", str(EXAMPLES / "scout-inject.yaml"), *common)
        try:
            head = _wait_for_line(judge, "waiting")
            fleet = run_pfp(
                "fleet", "--team", str(EXAMPLES / "team-scout.yaml"), *common,
                "--until-arrived", "--duration-s", "200", timeout=120,
            )  # fmt: skip
            out, err = judge.communicate(timeout=60)
        finally:
            if judge.poll() is None:
                judge.kill()
    assert fleet.returncode == 0, fleet.stdout[-3000:] + fleet.stderr
    assert "team alpha put: lead r1, follow m1, controller m1 of r1" in fleet.stdout
    out = "".join(head) + out
    assert "add threat e1" in out, out
    for line in (
        "PASS  m1 enters only ground r1 cleared (8 m wide)",
        "PASS  r1 within 60 m of m1 >= 99 % of the time",
        "PASS  m1 keeps at least 5 m from r1",
        "PASS  m1 arrives within 200 s",
    ):
        assert line in out, out + err
    assert judge.returncode == 0, out + err
