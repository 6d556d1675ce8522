"""Every client takes ``--zenoh-config``, so a user/password identity from ``pfp acl`` can be used.

A Python router is opened from the config ``pfp acl`` wrote (user/password
required, deny by default), as tests/proc/test_acl.py does.  ``pfp fleet`` given the
fleet's client file joins it and its units' states reach an observer;
``pfp health`` and ``pfp status`` take where and who from the observer's file,
and without it are refused at the router.  A missing or invalid file is
one line naming ``--zenoh-config``, exit 2, for every client command.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import zenoh

from pfp_service.cli import main as pfp_main
from tests.conftest import run_pfp
from tests.zenoh_util import Inbox, free_port

pytestmark = pytest.mark.proc

M = "zcfg"
TEAM = """name: zcfg-test
units:
  - {id: u1, start: [0, 0], goal: [10, 10]}
"""


@pytest.fixture(scope="module")
def acl_router(tmp_path_factory):
    """A router that requires the users ``pfp acl`` generated; yields (acl dir, endpoint, team file)."""
    tmp = tmp_path_factory.mktemp("zcfg")
    team = tmp / "team.yaml"
    team.write_text(TEAM)
    port = free_port()
    out = tmp / "acl"
    argv = ["acl", str(team), "--out", str(out), "--mission", M, "--quiet"]
    argv += ["--listen", f"tcp/127.0.0.1:{port}", "--connect-host", f"127.0.0.1:{port}"]
    assert pfp_main(argv) == 0
    router = zenoh.open(zenoh.Config.from_file(str(out / "zenoh-router.json5")))
    try:
        yield out, f"tcp/127.0.0.1:{port}", team
    finally:
        router.close()


def _fleet(team: Path, *session: str) -> subprocess.CompletedProcess[str]:
    argv = ["fleet", "--team", str(team), "--mission", M, "--no-goals", "--speed-up", "5"]
    return run_pfp(*argv, "--duration-s", "3", *session, timeout=120)


def test_fleet_joins_a_usrpwd_router_with_its_acl_identity(acl_router):
    out, _endpoint, team = acl_router
    observer = zenoh.open(zenoh.Config.from_file(str(out / "clients" / "observer.json5")))
    try:
        states = Inbox(observer, f"mumt/{M}/**/unit/*/state")  # fleet publishes on the shard key
        done = _fleet(team, "--zenoh-config", str(out / "clients" / "fleet.json5"))
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
        assert states.get(timeout=10)["position"] == [0.0, 0.0]  # u1's state came through the router
    finally:
        observer.close()


def test_without_the_identity_the_router_refuses_the_client(acl_router):
    _out, endpoint, _team = acl_router
    done = run_pfp("health", "--mission", M, "--connect", endpoint, "--timeout", "1", timeout=60)
    assert done.returncode == 1
    assert "--connect" in done.stderr, done.stderr  # refused at open: not even "no planner answered"


def test_status_and_health_use_the_file_for_where_and_who(acl_router):
    out, _endpoint, _team = acl_router
    observer = str(out / "clients" / "observer.json5")
    for command in ("health", "status"):
        done = run_pfp(command, "--mission", M, "--zenoh-config", observer, "--timeout", "1", timeout=60)
        assert done.returncode == 1  # joined the router (the file's endpoint and user); no planner runs
        assert done.stderr.strip() == f"pfp {command}: no planner of mission {M!r} answered within 1 s"


CLIENTS = {
    "fleet": ["fleet", "--generate", "1"],
    "inject": ["inject", "SCRIPT"],
    "status": ["status"],
    "health": ["health"],
    "map": ["map"],
    "handheld": ["handheld", "--unit", "u1"],
}


@pytest.mark.parametrize("bad", ["missing", "invalid"])
@pytest.mark.parametrize("command", sorted(CLIENTS))
def test_a_bad_zenoh_config_is_one_line_exit_2(command, bad, tmp_path):
    if command == "handheld":
        pytest.importorskip("textual")
    if command == "map":
        pytest.importorskip("aiohttp")
    script = tmp_path / "script.yaml"
    script.write_text("name: s\nduration_s: 5\ntimeline: []\n")
    path = tmp_path / "zenoh.json5"
    if bad == "invalid":
        path.write_text("{mode: client,,, nope")
    argv = [str(script) if a == "SCRIPT" else a for a in CLIENTS[command]]
    done = run_pfp(*argv, "--zenoh-config", str(path), timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"pfp {command}: --zenoh-config: {path}: "), lines[0]
    assert "Traceback" not in done.stderr and ".rs:" not in done.stderr
