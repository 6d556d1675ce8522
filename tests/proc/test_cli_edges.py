"""Every command as a first-time user meets it: bad files, bad flags, closed pipes, help and defaults.

Each case runs ``pfp`` in a subprocess, as a user would, and expects one line on
stderr naming the file or flag, exit code 2, and never a traceback.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import EXAMPLES, ROOT, run_pfp
from tests.zenoh_util import free_port

# Every command that reads a file, with the argument list around the file (FILE is replaced).
FILE_TAKERS = {
    "plan": ["plan", "FILE"],
    "serve --config": ["serve", "--config", "FILE"],
    "serve --zenoh-config": ["serve", "--zenoh-config", "FILE"],
    "fleet --team": ["fleet", "--team", "FILE", "--connect", "tcp/127.0.0.1:1"],
    "inject": ["inject", "FILE", "--check"],
    "demo --team": ["demo", "--quick", "--team", "FILE", "--out", "OUT"],
    "demo --script": ["demo", "--quick", "--script", "FILE", "--out", "OUT"],
}
SUFFIX = {"plan": ".yaml", "serve --config": ".toml", "serve --zenoh-config": ".json5"}


def _bad_file(kind: str, tmp: Path, suffix: str) -> Path:
    p = tmp / f"{kind}{suffix}"
    if kind == "missing":
        return p
    if kind == "directory":
        p.mkdir()
    elif kind == "binary":
        p.write_bytes(bytes(range(256)) * 64)
    elif kind == "non-utf8":
        p.write_bytes("name: caf\u00e9\n".encode("latin-1"))
    elif kind == "huge":
        with open(p, "wb") as f:
            f.truncate(17 * 1024 * 1024)  # sparse: quick to make, still 17 MiB to read
    return p


def _one_line_exit_2(r: subprocess.CompletedProcess[str]) -> str:
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode == 2, (r.returncode, r.stdout[-500:], r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert ".rs:" not in lines[0] and "Json5Err" not in lines[0], lines[0]
    return lines[0]


@pytest.mark.proc
@pytest.mark.parametrize("kind", ["missing", "directory", "binary", "non-utf8", "huge"])
@pytest.mark.parametrize("command", sorted(FILE_TAKERS))
def test_every_bad_file_is_one_line_exit_2(tmp_path, command, kind):
    path = _bad_file(kind, tmp_path, SUFFIX.get(command, ".yaml"))
    args = [
        str(path) if a == "FILE" else str(tmp_path / "o.png") if a == "OUT" else a
        for a in FILE_TAKERS[command]
    ]
    line = _one_line_exit_2(run_pfp(*args, timeout=180))  # a busy shared machine: generous
    assert line.startswith(f"pfp {command.split()[0]}: ")
    assert path.name in line, line  # it names the file


BAD_FLAGS = [
    (["plan", "S", "--lambda", "3"], "pfp plan: --lambda: only goes with --planner optimal"),
    (["plan", "S", "--cells", "50"], "pfp plan: --cells: only goes with --planner optimal"),
    (
        ["plan", "S", "--planner", "optimal", "--delta", "1"],
        "pfp plan: --delta: only goes with --planner pfp",
    ),
    (["plan", "S", "--max-iter", "999999999999"], "--max-iter: must be 1 to 10,000,000"),
    (["serve", "--lookahead", "1000"], "--lookahead: must be 0 to 100"),
    (["plan", "S", "--step", "1e300"], "--step: must be a finite number >= 0.001 (at most 1e+09)"),
    (["serve", "--listen", "notanendpoint"], "pfp serve: --listen: 'notanendpoint' is not an endpoint"),
    (["serve", "--mission", "a/b"], "--mission: 'a/b' is not 1-64 characters"),
    (["fleet", "--generate", "100000000"], "--generate: at most 10000 units per fleet process"),
    (["fleet", "--team", "T", "--seed", "3"], "pfp fleet: --seed: only goes with --generate"),
    (["fleet", "--generate", "3", "--connect", "bogus"], "pfp fleet: --connect: 'bogus' is not an endpoint"),
    (["inject", "I", "--mode", "bogus"], "argument --mode: invalid choice"),
    (["health", "--connect", "notanendpoint"], "pfp health: --connect: 'notanendpoint' is not an endpoint"),
    (["status", "--connect", "notanendpoint"], "pfp status: --connect: 'notanendpoint' is not an endpoint"),
    (["handheld", "--unit", "u1", "--nmea-rate", "2"], "pfp handheld: --nmea-rate: only goes with --nmea"),
    (["demo", "--out", "x.jpg"], "pfp demo: --out: x.jpg: must end in .png"),
]


@pytest.mark.proc
@pytest.mark.parametrize(("args", "fragment"), BAD_FLAGS, ids=[" ".join(a) for a, _ in BAD_FLAGS])
def test_every_bad_flag_is_one_line_exit_2(args, fragment):
    subst = {"S": str(EXAMPLES / "paper-simple.yaml"), "T": str(EXAMPLES / "demo-team.yaml")}
    subst["I"] = str(EXAMPLES / "figure8-inject.yaml")
    line = _one_line_exit_2(run_pfp(*[subst.get(a, a) for a in args], timeout=60))
    assert fragment in line, line


@pytest.mark.proc
def test_a_port_in_use_is_one_line_without_source_paths():
    port = free_port()
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", port))
        s.listen()
        line = _one_line_exit_2(run_pfp("serve", "--listen", f"tcp/127.0.0.1:{port}", timeout=60))
    assert line == f"pfp serve: --listen: cannot listen on tcp/127.0.0.1:{port}: address already in use"


@pytest.mark.proc
@pytest.mark.parametrize("command", ["health", "status"])
def test_no_router_is_exit_1_and_one_line(command):
    r = run_pfp(command, "--connect", f"tcp/127.0.0.1:{free_port()}", timeout=60)
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert r.stderr.strip().startswith(f"pfp {command}: --connect: no router answers at tcp/127.0.0.1:")


@pytest.mark.proc
@pytest.mark.parametrize(
    "args",
    [["plan", str(EXAMPLES / "paper-simple.yaml")], ["plan", str(EXAMPLES / "paper-simple.yaml"), "--json"]],
)
def test_a_closed_pipe_is_one_line_exit_2(args):
    """``pfp plan X | head -1``: the reader leaves early; no BrokenPipeError traceback."""
    # `true` leaves without reading: the plan takes a moment, so pfp writes into a closed pipe
    script = f"{sys.executable} -m pfp_service {' '.join(args)} | true; echo ${{PIPESTATUS[0]}} >&2"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    r = subprocess.run(["bash", "-c", script], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert "Traceback" not in r.stderr and "Exception ignored" not in r.stderr, r.stderr
    assert lines[-1] == "2", r.stderr  # pfp's own exit code
    assert lines[:-1] == ["pfp plan: stdout: the reader closed the pipe before the output was written"]


@pytest.mark.proc
def test_pfp_alone_prints_help():
    r = run_pfp(timeout=60)
    assert r.returncode == 0 and r.stderr == ""
    assert r.stdout.startswith("usage: pfp")
    for command in ("demo", "fleet", "handheld", "health", "inject", "plan", "schemas", "serve", "status"):
        assert f"    {command} " in r.stdout, command
    r = run_pfp("bench", timeout=60)
    assert r.returncode == 0 and "engine" in r.stdout


# The commands of this project's CLI work; acl, map and tak are checked by their own tests.
HELP_CHECKED = (
    "bench",
    "demo",
    "fleet",
    "handheld",
    "health",
    "inject",
    "plan",
    "schemas",
    "serve",
    "status",
)


@pytest.mark.unit
def test_every_flag_has_help_and_shows_its_default():
    from pfp_service.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    checked = 0
    for name, p in sub.choices.items():  # type: ignore[union-attr]
        if name not in HELP_CHECKED:
            continue
        formatter = p._get_formatter()
        for action in p._actions:
            if not action.option_strings or action.dest == "help":
                continue
            assert action.help, f"pfp {name} {action.option_strings[0]} has no help"
            text = formatter._get_help_string(action) or ""
            if action.default not in (None, False):
                assert "default" in text, f"pfp {name} {action.option_strings[0]}: {text!r}"
            checked += 1
    assert checked > 80


@pytest.mark.proc
def test_plan_exit_codes_say_whether_the_goal_was_reached(tmp_path):
    assert run_pfp("plan", str(EXAMPLES / "paper-simple.yaml"), timeout=60).returncode == 0
    trap = tmp_path / "trap.yaml"
    trap.write_text(
        "start: [0, 0]\ngoal: [20, 0]\nplanner: {escape: none}\n"
        "threats:\n  - {position: [10, 0], sigma_range: 2, sigma_lateral: 2, weight: 5}\n"
    )
    r = run_pfp("plan", str(trap), "--plot", str(tmp_path / "trap.png"), timeout=60)
    assert r.returncode == 1 and "trapped" in r.stdout and r.stderr == ""
    assert (tmp_path / "trap.png").stat().st_size > 10_000
    r = run_pfp("plan", str(EXAMPLES / "paper-simple.yaml"), "--max-iter", "3", "--json", timeout=60)
    assert r.returncode == 1 and '"status":"max_iter"' in r.stdout
