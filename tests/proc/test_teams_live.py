"""Teams on a live planner (``pfp serve`` on loopback Zenoh): put, judged, rejected, stored and restored; ``pfp fleet
--team`` puts a file's teams and ``pfp status`` lists them."""

from __future__ import annotations

import uuid

import pytest

from pfp_service.wire import decode_world_snapshot, keys
from tests.conftest import run_pfp
from tests.unit.test_team_files import ALPHA, UNITS
from tests.zenoh_util import Inbox, client, planner_process, put_in_force, put_json

pytestmark = pytest.mark.proc


def _snapshot(s, mission: str):
    (reply,) = [r for r in s.get(keys.worlds(mission), timeout=5) if r.ok is not None]
    return decode_world_snapshot(reply.ok.payload.to_bytes())


def test_a_team_on_the_wire_is_judged_rejected_on_a_clash_and_restored_after_a_restart(tmp_path):
    mission = "tl" + uuid.uuid4().hex[:8]
    state = str(tmp_path / "state")
    with planner_process("--state-dir", state, mission=mission) as (endpoint, _p), client(endpoint) as s:
        direction = Inbox(s, keys.unit_direction(mission, "r1"))
        rejected = Inbox(s, keys.event(mission, "rejected"))
        team = {"controller": "m1", "robots": ["r1"], "radio_range_m": 500}
        put_in_force(
            s,
            mission,
            {keys.team(mission, "alpha"): team, keys.unit_goal(mission, "r1"): {"position": [200, 0]}},
        )
        put_json(s, keys.unit_state(mission, "m1"), {"position": [0, 0], "speed_mps": 0})
        put_json(s, keys.unit_state(mission, "r1"), {"position": [10, 0], "seq": 1, "speed_mps": 1})
        d = direction.get(timeout=10, where=lambda d: d.get("seq") == 1)
        assert d["vector"] == [0.0, 0.0] and d["reason"] == "team alpha: lost link: controller m1 has stopped"
        put_json(s, keys.team(mission, "bravo"), {"controller": "r1", "robots": ["x"]})  # r1 is alpha's
        e = rejected.get(timeout=10, where=lambda e: e.get("key") == keys.team(mission, "bravo"))
        assert e["field"] == "$.controller" and "already in team 'alpha'" in e["reason"]
        assert [t.id for t in _snapshot(s, mission).teams] == ["alpha"]
    with planner_process("--state-dir", state, mission=mission) as (endpoint, _p), client(endpoint) as s:
        (t,) = _snapshot(s, mission).teams
        assert t.id == "alpha" and t.team.robots == ["r1"] and t.team.radio_range_m == 500


def test_pfp_fleet_puts_the_files_teams_and_pfp_status_lists_them(tmp_path):
    mission = "tf" + uuid.uuid4().hex[:8]
    p = tmp_path / "team.yaml"
    # the followers' goals on the lead's way: a goal off its corridor is never reached (they hold at its edge)
    p.write_text(
        UNITS.replace("goal: [200, 10]", "goal: [190, 15]").replace("goal: [200, 20]", "goal: [180, 15]")
        + ALPHA
    )
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, _p):
        r = run_pfp(
            "fleet", "--team", str(p), "--connect", endpoint, "--mission", mission,
            "--speed-up", "20", "--until-arrived", "--duration-s", "300", timeout=200,
        )  # fmt: skip
        assert "team alpha put: lead r1, follow m1 m2, controller m1 of r1 r2" in r.stdout, (
            r.stdout + r.stderr
        )
        assert r.returncode == 0 and "all arrived" in r.stdout, r.stdout[-2000:] + r.stderr
        st = run_pfp("status", "--connect", endpoint, "--mission", mission, timeout=60)
        assert st.returncode == 0, st.stderr
        rows = [line.split() for line in st.stdout.splitlines()]
        assert ["alpha", "r1", "m1", "m2", "m1", "r1", "r2", "-"] in rows, st.stdout
