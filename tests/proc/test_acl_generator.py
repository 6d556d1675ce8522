"""``pfp acl``'s generator itself: the grants and configs it writes (split from ``test_acl``)."""

from __future__ import annotations

import queue

import pytest

from pfp_service.cli import main as pfp_main
from tests.proc.test_acl import NOT_DELIVERED_S, TEAM, M, Router, _never, _settle
from tests.zenoh_util import Inbox, free_port, put_json

pytestmark = pytest.mark.proc


# -- the generator itself ---------------------------------------------------------------------
def test_pfp_acl_keeps_passwords_across_runs_and_hides_them(tmp_path):
    team = tmp_path / "team.yaml"
    team.write_text(TEAM)
    out = tmp_path / "acl"
    assert pfp_main(["acl", str(team), "--out", str(out), "--quiet"]) == 0
    first = (out / "credentials.txt").read_text()
    assert pfp_main(["acl", str(team), "--out", str(out), "--quiet"]) == 0
    assert (out / "credentials.txt").read_text() == first
    users = [line.split(":")[0] for line in first.splitlines()]
    assert users[-2:] == ["unit-u1", "unit-u2"] and "planner" in users
    for secret in [out / "credentials.txt", *(out / "clients").glob("*.json5")]:
        assert secret.stat().st_mode & 0o077 == 0, secret


@pytest.mark.parametrize(
    "args, message",
    [
        (["--role", "x=wizard"], "--role: x=wizard: unknown role (expected one of: planner, fleet,"),
        (["--role", "unit-u1=observer"], "names starting with 'unit-' are the units'"),
        (["--role", "nope"], "expected NAME=ROLE[,ROLE...]"),
        (["--mission", "a/b"], "--mission: 'a/b' is not 1-64 characters"),
    ],
)
def test_pfp_acl_bad_input_is_one_line_and_exit_2(tmp_path, args, message):
    from tests.conftest import run_pfp

    team = tmp_path / "team.yaml"
    team.write_text(TEAM)
    done = run_pfp("acl", str(team), "--out", str(tmp_path / "o"), *args)
    assert done.returncode == 2
    assert message in done.stderr and done.stderr.count("\n") == 1, done.stderr
    assert "Traceback" not in done.stderr


def test_no_unit_goals_leaves_goals_to_commanders():
    from pfp_service.node.access import Mission, principals_for

    def goal_writers(own_goal: bool) -> set[str]:
        ps = principals_for(Mission("m", ("planner",), ("u1",), own_goal), {"commander": ("commander",)})
        return {
            p.name
            for p in ps
            for g in p.grants
            if g.flow == "ingress" and "put" in g.messages and any(k.endswith("/goal") for k in g.key_exprs)
        }

    assert goal_writers(True) == {"commander", "unit-u1"}
    assert goal_writers(False) == {"commander"}


def test_planners_sharing_a_mission_each_hold_only_their_own_token(tmp_path):
    """--planner-id twice (scale-out): each planner's identity holds its own token and not the other's."""
    port = free_port()
    team = tmp_path / "team.yaml"
    team.write_text(TEAM)
    out = tmp_path / "acl"
    argv = ["acl", str(team), "--out", str(out), "--mission", M, "--quiet", "--planner-id", "p1"]
    argv += ["--planner-id", "p2", "--listen", f"tcp/127.0.0.1:{port}", "--connect-host", f"127.0.0.1:{port}"]
    assert pfp_main(argv) == 0
    r = Router(out, port, tls=False)
    try:
        with r.as_("p1") as p1, r.as_("p2") as p2, r.as_("observer") as obs:
            seen: queue.Queue[str] = queue.Queue()
            sub = obs.liveliness().declare_subscriber(
                f"mumt/{M}/alive/planner/*", lambda s: seen.put(str(s.key_expr)), history=True
            )
            _settle()
            spoof = p1.liveliness().declare_token(f"mumt/{M}/alive/planner/p2")
            with pytest.raises(queue.Empty):  # p1 cannot stand in for p2
                seen.get(timeout=NOT_DELIVERED_S)
            own = p2.liveliness().declare_token(f"mumt/{M}/alive/planner/p2")
            assert seen.get(timeout=5) == f"mumt/{M}/alive/planner/p2"
            mine = p1.liveliness().declare_token(f"mumt/{M}/alive/planner/p1")
            assert seen.get(timeout=5) == f"mumt/{M}/alive/planner/p1"
            # each planner sees the other's token (how two planners on one mission notice each other)
            other = [
                str(r.ok.key_expr)
                for r in p2.liveliness().get(f"mumt/{M}/alive/planner/*", timeout=2)
                if r.ok
            ]
            assert f"mumt/{M}/alive/planner/p1" in other
            # scale-out: a planner shares a unit's mission with the other; a unit cannot
            missions = Inbox(p2, f"mumt/{M}/unit/*/mission")
            _settle()
            with r.as_("unit-u1") as u1:
                put_json(u1, f"mumt/{M}/unit/u1/mission", {"from": "u1"})
                put_json(p1, f"mumt/{M}/unit/u1/mission", {"from": "p1"})
                assert missions.get() == {"from": "p1"}
                _never(missions, "a unit's own mission record")
            for h in (spoof, own, mine, sub):
                h.undeclare()
    finally:
        r.session.close()
