"""The docs cannot rot: every command README.md and docs/*.md show is run, as a user would run it.

Each ```sh block (and ```console block, its ``$ `` lines) is one shell session, run in a scratch
directory holding ``examples/`` and ``docker/`` (linked) and a copy of ``schemas/``:

* a ``pfp ...`` (or ``.venv/bin/pfp``) or ``python FILE.py`` line is run; ``make``, ``pip``,
  ``export``, ``kill``, ``docker`` ... lines are what a person types around them and are not;
  any other line fails the test, so nothing new slips past unrun;
* a line ending in ``&`` runs in the background: a long-running command (serve, map, tak,
  handheld, a fleet without an end, a router) must still be up when the block ends, and then
  stops on SIGTERM with exit 0; a finite one (inject) must end with exit 0 by the block's
  ``wait`` line;
* any other line must exit 0 (or N, when its comment says "(exit N)"), or, when long-running, come
  up (a log line, an answering port, a rendered screen) and stop on SIGTERM with exit 0;
* nothing may print a traceback.

A command is changed only where the machine demands it: port 7447 becomes a free port (a
block that starts a planner gets its own, the others talk to one planner shared by the
module), a client without ``--connect`` or ``--zenoh-config`` is pointed at it, ``pfp serve``
as a router listens there, ``pfp map`` serves on a free local port, a TAK server host is a
local listener, each block keeps durable state in its own directory, and benchmarks run
with small arguments (``SHRINK``).  ```python and ```toml blocks whose first line is
``# NAME`` are written as ``NAME`` (7447 rewritten the same way) before a block runs;
```text blocks are never run.

In process beside them: ``test_docs_in_process``.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import pty
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import termios
import threading
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.doc_blocks import (
    DOC_PORT,
    PFP,
    PYTHON,
    ROOT,
    SESSION,
    Block,
    Line,
    long_running,
    named_files,
    runnable,
    session_lines,
    sh_blocks,
)
from tests.zenoh_util import free_port, planner_process

# Benchmarks at a size the test can afford: flags dropped, flags added (argparse keeps the last).
PREVIEW_LOAD = ["--live-threats", "50", "--max-p99-ms", "10000"]
SHRINK: dict[str, tuple[set[str], list[str]]] = {
    "engine": (set(), ["--quick", "--no-scale", "--repeat", "1", "--baseline-repeat", "1"]),
    "roundtrip": (set(), ["--count", "50"]),
    # the live rows (1,000 units) and the 10 m grid are test_terrain_cli's bench test's, at 40 m
    "terrain": ({"--check"}, ["--repeat", "2", "--cell", "40", "--no-live"]),
    "service": (
        {"--find-max", "--echo"},
        ["--units", "20", "--rate", "5", "--threats", "5", "--duration", "2", "--no-storm", "--no-fanout"],
    ),
    # a pass mark for a quiet machine: here the test checks the command runs, not the machine's figures
    "previews": (set(), ["--scenario", "storm", "--queries", "10", "--threads", "2", *PREVIEW_LOAD]),
    "failover": (set(), ["--planners", "2", "--units", "6", "--kills", "1"]),
    "memory": (set(), ["--units", "20", "--threats", "5", "--idle-s", "3", "--load-s", "2"]),
    "vehicles": (set(), ["--quick"]),
    "convergence": (set(), ["--quick"]),
    "quality": (set(), ["--scenarios", "2", "--modes", "none,contour", "--cells", "60"]),
}
# Doc lines another test runs as its own, with more to check than an exit code: the line's words
# but ``--speed-up N`` -> that test (its module and function).  A demo's test sets its own speed-up,
# one a neighbour's load cannot make late, so it runs beside others (here the line ran ``alone``);
# the fuzz's runs it at a test's size (here it ran again, 30 s of fixed phases).
# ``test_every_line_run_elsewhere_is_run_there`` holds the other side of the bargain.
RUN_ELSEWHERE: dict[tuple[str, ...], tuple[str, str]] = {
    ("pfp", "demo", "--quick"): (
        "tests/proc/test_demo.py",
        "test_demo_quick_runs_and_writes_summary_and_png",
    ),
    ("pfp", "demo", "--terrain"): (
        "tests/proc/test_demo_terrain.py",
        "test_the_terrain_demo_crosses_real_ground_and_every_expectation_holds",
    ),
    ("pfp", "bench", "fuzz"): (
        "tests/proc/test_fuzz_live.py",
        "test_a_planner_survives_malformed_input_on_every_key_and_queryable",
    ),
    ("pfp", "demo", "--teams"): (
        "tests/proc/test_demo_teams.py",
        "test_the_teaming_demo_gives_each_team_one_goal_and_every_expectation_holds",
    ),
}


def _without_speed_up(words: list[str]) -> tuple[str, ...]:
    out, skip = [], False
    for w in words:
        if skip:
            skip = False
        elif w == "--speed-up":
            skip = True
        elif not w.startswith("--speed-up="):
            out.append(w)
    return tuple(out)


def run_here(line: Line) -> bool:
    """A line this test runs: runnable, and not one ``RUN_ELSEWHERE`` names."""
    return runnable(line) and _without_speed_up(line.words) not in RUN_ELSEWHERE


START_TIMEOUT_S = 90.0
RUN_TIMEOUT_S = 400.0


# -- running them ------------------------------------------------------------------------------------
def flag(words: list[str], name: str) -> str | None:
    for i, w in enumerate(words):
        if w == name and i + 1 < len(words):
            return words[i + 1]
        if w.startswith(name + "="):
            return w.split("=", 1)[1]
    return None


@dataclass
class Proc:
    line: Line
    popen: subprocess.Popen[bytes]
    log: Path
    ready: str  # what "started" means, for messages
    http_port: int | None = None
    pty_out: list[bytes] = field(default_factory=list)

    def output(self) -> str:
        text = self.log.read_text(errors="replace") if self.log.exists() else ""
        return text + b"".join(self.pty_out).decode(errors="replace")


class TakServer:
    """A local TCP listener standing in for a TAK server's streaming port."""

    def __init__(self) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen()
        self.port = self.sock.getsockname()[1]
        self.connected = threading.Event()
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        with contextlib.suppress(OSError):
            while True:
                conn, _ = self.sock.accept()
                self.connected.set()
                threading.Thread(target=self._drain, args=(conn,), daemon=True).start()

    @staticmethod
    def _drain(conn: socket.socket) -> None:
        with conn, contextlib.suppress(OSError):
            while conn.recv(65536):
                pass

    def close(self) -> None:
        self.sock.close()


class Session:
    """One ```sh block, run as a shell would, with what the machine needs changed."""

    def __init__(self, block: Block, work: Path, shared_endpoint: str, tak: TakServer) -> None:
        self.block = block
        self.work = work
        self.lines = [ln for ln in session_lines(block) if run_here(ln) or ln.program == "wait"]
        own = any(_starts_a_router(ln) for ln in self.lines)
        self.port = str(free_port()) if own else shared_endpoint.rsplit(":", 1)[1]
        self.tak = tak
        self.state = Path(tempfile.mkdtemp(prefix="state-", dir=work))
        self.procs: list[Proc] = []

    # rewriting
    def localise(self, text: str) -> str:
        text = text.replace(f":{DOC_PORT}", f":{self.port}")
        text = text.replace("10.0.0.1:", "127.0.0.1:")
        return text.replace("takserver:8087", f"127.0.0.1:{self.tak.port}")

    def argv(self, line: Line) -> tuple[list[str], int | None]:
        words = [self.localise(w) for w in line.words]
        http_port = None
        if line.program in PYTHON:
            return [sys.executable, *words[1:]], None
        args = words[1:]
        sub = line.subcommand
        if sub in SESSION and flag(args, "--connect") is None and flag(args, "--zenoh-config") is None:
            args += ["--connect", f"tcp/127.0.0.1:{self.port}"]
        if sub == "serve":
            mode = flag(args, "--mode") or "router"
            given = [flag(args, f) for f in ("--listen", "--config", "--zenoh-config")]
            if mode == "router" and given == [None, None, None]:
                args += ["--listen", f"tcp/127.0.0.1:{self.port}"]
        if sub == "map":
            http_port = free_port()
            args = [a for i, a in enumerate(args) if a != "--http" and (i == 0 or args[i - 1] != "--http")]
            args += ["--http", f"127.0.0.1:{http_port}"]
        if sub == "bench":
            drop, add = SHRINK[args[1]]
            args = [a for a in args if a not in drop] + add
        return [sys.executable, "-m", "pfp_service", *args], http_port

    def env(self, line: Line) -> dict[str, str]:
        return {
            **os.environ,
            "PYTHONUNBUFFERED": "1",
            "XDG_STATE_HOME": str(self.state),
            "COLUMNS": "100",
            "LINES": "40",
            **line.env,
        }

    # processes
    def start(self, line: Line) -> Proc:
        argv, http_port = self.argv(line)
        log = Path(tempfile.mkstemp(prefix="out-", suffix=".txt", dir=self.work)[1])
        if line.subcommand == "handheld":  # a terminal UI: it refuses to run without a terminal
            master, slave = pty.openpty()
            fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 100, 0, 0))
            popen = subprocess.Popen(
                argv, cwd=self.work, env={**self.env(line), "TERM": "xterm-256color"},
                stdin=slave, stdout=slave, stderr=slave, start_new_session=True,
            )  # fmt: skip
            os.close(slave)
            proc = Proc(line, popen, log, "its screen shows the planner's status", http_port)
            threading.Thread(target=_read_pty, args=(master, proc.pty_out), daemon=True).start()
        else:
            with log.open("wb") as out:
                popen = subprocess.Popen(
                    argv, cwd=self.work, env=self.env(line), stdout=out, stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                )  # fmt: skip
            proc = Proc(line, popen, log, "", http_port)
        self.procs.append(proc)
        return proc

    def wait_ready(self, proc: Proc) -> None:
        """Until the command is up (its own condition); fails if it exits or errs first."""
        sub = proc.line.subcommand
        checks = {
            "serve": ("its log says 'planner ready'", lambda: "planner ready" in proc.output()),
            "map": ("its page answers", lambda: _http_ok(proc.http_port)),
            "tak": ("it connected to the TAK server", self.tak.connected.is_set),
            "handheld": ("its screen shows a planner status", lambda: _tui_ready(proc.output())),
        }
        if proc.line.program in PYTHON:  # a router from a config: up when its port answers
            checks[""] = (f"port {self.port} answers", lambda: _port_open(int(self.port)))
        what, ready = checks.get(sub, ("", lambda: True))
        if sub == "fleet":
            what, ready = "it printed progress", lambda: bool(proc.output().strip())
        deadline = time.monotonic() + START_TIMEOUT_S
        while not ready():
            code = proc.popen.poll()
            assert code is None, (
                f"{proc.line.text!r} exited with {code} before {what}:\n{proc.output()[-3000:]}"
            )
            assert time.monotonic() < deadline, (
                f"{proc.line.text!r}: not up in {START_TIMEOUT_S:g} s ({what})"
            )
            time.sleep(0.1)
        assert "Traceback" not in proc.output(), f"{proc.line.text!r}:\n{proc.output()[-3000:]}"

    def stop(self, proc: Proc) -> None:
        """SIGTERM; a long-running command then exits 0 with no traceback."""
        assert proc.popen.poll() is None, (
            f"{proc.line.text!r} did not stay up (exit {proc.popen.returncode}):\n{proc.output()[-3000:]}"
        )
        proc.popen.send_signal(signal.SIGTERM)
        try:
            code = proc.popen.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.popen.kill()
            proc.popen.wait()
            raise AssertionError(f"{proc.line.text!r} did not stop within 30 s of SIGTERM") from None
        assert code == 0, f"{proc.line.text!r}: exit {code} after SIGTERM:\n{proc.output()[-3000:]}"
        assert "Traceback" not in proc.output(), f"{proc.line.text!r}:\n{proc.output()[-3000:]}"

    def finish(self, proc: Proc) -> None:
        """A finite command: exit 0 (or the code its doc line says), no traceback."""
        try:
            code = proc.popen.wait(timeout=RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.popen.kill()
            proc.popen.wait()
            raise AssertionError(f"{proc.line.text!r} did not finish in {RUN_TIMEOUT_S:g} s") from None
        want = proc.line.exit_code
        assert code == want, f"{proc.line.text!r}: exit {code}, not {want}:\n{proc.output()[-3000:]}"
        assert "Traceback" not in proc.output(), f"{proc.line.text!r}:\n{proc.output()[-3000:]}"

    def run(self) -> None:
        background: list[Proc] = []
        try:
            for line in self.lines:
                t0 = time.monotonic()
                if line.program == "wait":
                    for proc in [p for p in background if not long_running(p.line)]:
                        self.finish(proc)
                        background.remove(proc)
                    continue
                proc = self.start(line)
                if line.background:
                    background.append(proc)
                    if long_running(line):
                        self.wait_ready(proc)
                elif long_running(line):
                    self.wait_ready(proc)
                    self.stop(proc)
                else:
                    self.finish(proc)
                print(f"{time.monotonic() - t0:6.1f} s  {line.text}")
            for proc in reversed(background):  # the planner last: clients first, as a shell's kill would
                if long_running(proc.line) or proc.popen.poll() is None:
                    self.stop(proc)
                else:
                    self.finish(proc)
        finally:
            for proc in self.procs:
                if proc.popen.poll() is None:
                    proc.popen.kill()
                    proc.popen.wait()


def _starts_a_router(line: Line) -> bool:
    """A planner on its own embedded router, or a router from a config: the block gets its own port."""
    if line.program in PYTHON:
        return line.background
    if line.subcommand != "serve":
        return False
    flags = [flag(line.words, f) for f in ("--config", "--zenoh-config")]
    return (flag(line.words, "--mode") or "router") == "router" and flags == [None, None]


def _read_pty(fd: int, into: list[bytes]) -> None:
    with contextlib.suppress(OSError):
        while chunk := os.read(fd, 65536):
            into.append(chunk)
    with contextlib.suppress(OSError):
        os.close(fd)


def _http_ok(port: int | None) -> bool:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2) as r:
            return r.status == 200
    except OSError:
        return False


def _port_open(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(1)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _tui_ready(screen: str) -> bool:
    plain = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen)
    return any(status in plain for status in ("EN ROUTE", "ESCAPING", "ARRIVED"))


# -- fixtures ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """A scratch directory as a checkout looks to the commands: examples, docker, schemas."""
    path = tmp_path_factory.mktemp("docs")
    (path / "examples").symlink_to(ROOT / "examples")
    (path / "docker").symlink_to(ROOT / "docker")
    shutil.copytree(ROOT / "schemas", path / "schemas")
    return path


@pytest.fixture(scope="module")
def shared_planner() -> Iterator[str]:
    with planner_process("--state-dir", "none") as (endpoint, _proc):
        yield endpoint


@pytest.fixture(scope="module")
def tak_server() -> Iterator[TakServer]:
    server = TakServer()
    yield server
    server.close()


SH_BLOCKS = [b for b in sh_blocks() if any(run_here(ln) for ln in session_lines(b))]


def against_the_clock(block: Block) -> bool:
    """A block that plays a mission with expectations on a sped-up clock (a demo, a script not only
    ``--check``ed): a neighbour's load can make it miss a deadline it keeps alone, so it runs ``alone``."""
    return any(
        ln.program in PFP and ln.words[1:2] in (["demo"], ["inject"]) and "--check" not in ln.words
        for ln in session_lines(block)
        if run_here(ln)
    )


BLOCK_PARAMS = [
    pytest.param(b, id=b.name, marks=[pytest.mark.alone] if against_the_clock(b) else []) for b in SH_BLOCKS
]


@pytest.mark.multi
@pytest.mark.spread  # each block is whole in itself: the two workers each start their own shared planner
@pytest.mark.timeout(1200)
@pytest.mark.parametrize("block", BLOCK_PARAMS)
def test_every_command_the_docs_show_runs(
    block: Block, work: Path, shared_planner: str, tak_server: TakServer
):
    session = Session(block, work, shared_planner, tak_server)
    for name, text in named_files().items():
        (work / name).write_text(session.localise(text))
    session.run()


@pytest.mark.unit
def test_every_line_run_elsewhere_is_run_there():
    """Each doc line ``RUN_ELSEWHERE`` names is shown by a doc, and its test runs those very words."""
    shown = {
        _without_speed_up(ln.words)
        for b in sh_blocks()
        for ln in session_lines(b)
        if runnable(ln) and _without_speed_up(ln.words) in RUN_ELSEWHERE
    }
    assert shown == set(RUN_ELSEWHERE), f"no doc shows {set(RUN_ELSEWHERE) - shown}"
    for words, (module, function) in RUN_ELSEWHERE.items():
        source = (ROOT / module).read_text()
        body = source.split(f"def {function}(", 1)
        assert len(body) == 2, f"{module} has no {function}"
        call = body[1].split("\ndef ", 1)[0]
        assert all(f'"{w}"' in call for w in words[1:]), (
            f"{module}::{function} does not run {' '.join(words)}"
        )
