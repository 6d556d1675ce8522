"""``pfp demo --teams`` as a user runs it: two teams, each given one goal, a threat in the scout's way, and every
team expectation (both teams arrive, cleared ground only, the link kept, distance kept) held."""

from __future__ import annotations

import pytest

from tests.conftest import run_pfp

pytestmark = pytest.mark.proc


def test_the_teaming_demo_gives_each_team_one_goal_and_every_expectation_holds(tmp_path):
    out = tmp_path / "demo.png"
    r = run_pfp(
        "demo", "--teams", "--speed-up", "10", "--out", str(out), timeout=300
    )  # x10: a neighbour's load moves a x30 run's timing
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    text = r.stdout
    assert "add team alpha: r1 m1, its goal (200, 0)" in text and "add team bravo: u1 u2 u3" in text
    assert "add threat e1" in text  # it struck mid-route
    assert "PASS  team alpha arrives within 200 s" in text and "PASS  team bravo arrives within 200 s" in text
    assert "6/6 expectations held" in text
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
