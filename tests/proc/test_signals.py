"""Every long-running command stops cleanly: 0 on SIGTERM, 130 on SIGINT, within 10 s, no traceback.

Each command runs as a user runs it: ``pfp ...`` in a subprocess of its own
process group.  Ctrl-C is simulated the way a terminal sends it, SIGINT to the
whole group (the planner's worker processes get it too); a supervisor's stop
is SIGTERM to the process alone.  Each command must have got past its start
(a line it prints once its session and declarations are up) before the signal,
and must print the line it prints after closing them: the exit went through
the command's own cleanup, not around it.  ``pfp handheld`` runs on a
pseudo-terminal, as it needs one.
"""

from __future__ import annotations

import os
import pty
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh

from tests.zenoh_util import ROOT, free_port

pytestmark = pytest.mark.proc

STOP_WITHIN_S = 10.0
START_WITHIN_S = 90.0  # a cold start on a loaded 2-core machine (numba caches, Zenoh, Textual)
EXPECTED = {signal.SIGTERM: 0, signal.SIGINT: 130}
HOW = {"sigint-to-group": signal.SIGINT, "sigterm-to-process": signal.SIGTERM}

INJECT_SCRIPT = """name: long-wait
duration_s: 3600
timeline:
  - {do: add_threat, threat: e1, position: [5, 5], facing_deg: 0, sigma_range: 1, sigma_lateral: 1}
  - {do: wait, seconds: 3000}
"""


@pytest.fixture(scope="module")
def router():
    """A bare Zenoh router for the clients to join (no planner: stopping needs none)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", f'["{endpoint}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    try:
        yield endpoint
    finally:
        session.close()


class Output:
    """A growing text buffer fed by a reader thread (a pty master) or read back from a file."""

    def __init__(self) -> None:
        self.chunks: list[str] = []
        self.lock = threading.Lock()

    def add(self, text: str) -> None:
        with self.lock:
            self.chunks.append(text)

    @property
    def text(self) -> str:
        with self.lock:
            return "".join(self.chunks)


def _wait_for(what: Callable[[], bool], timeout_s: float, why: Callable[[], str]) -> None:
    deadline = time.monotonic() + timeout_s
    while not what():
        assert time.monotonic() < deadline, why()
        time.sleep(0.05)


def _command(name: str, endpoint: str, tmp: Path) -> tuple[list[str], str, str]:
    """The argv, the line it prints once running, and the line it prints after closing."""
    if name == "serve":  # its own embedded router
        own = f"tcp/127.0.0.1:{free_port()}"
        return (["serve", "--listen", own, "--state-dir", "none", "--mission", "sig"], "serving", "stopped")
    if name == "fleet":
        argv = ["fleet", "--generate", "3", "--connect", endpoint, "--mission", "sig", "--speed-up", "5"]
        return argv, "fleet generated", "fleet stops: stopped"
    if name == "inject":
        script = tmp / "long.yaml"
        script.write_text(INJECT_SCRIPT)
        return (
            ["inject", str(script), "--connect", endpoint, "--mission", "sig"],
            "add threat",
            "inject stops",
        )
    if name == "map":
        return (
            ["map", "--connect", endpoint, "--mission", "sig", "--http", "127.0.0.1:0"],
            "pfp map: mission sig at",
            "",
        )
    if name == "demo":
        return ["demo", "--quick", "--out", str(tmp / "demo.png")], "t=", "demo stopped"
    raise AssertionError(name)


def _signal(proc: subprocess.Popen[bytes], sig: signal.Signals) -> None:
    if sig is signal.SIGINT:
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole foreground group
    else:
        proc.send_signal(signal.SIGTERM)


def _stop_and_judge(proc: subprocess.Popen[bytes], sig: signal.Signals, out: Callable[[], str]) -> str:
    _signal(proc, sig)
    sent = time.monotonic()
    try:
        code = proc.wait(timeout=STOP_WITHIN_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        pytest.fail(f"still running {STOP_WITHIN_S:g} s after {sig.name}:\n{out()[-3000:]}")
    took = time.monotonic() - sent
    text = out()
    assert code == EXPECTED[sig], f"exit {code} after {sig.name} (expected {EXPECTED[sig]}):\n{text[-3000:]}"
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text[-3000:]
    print(f"{sig.name}: exit {code} in {took:.2f} s")
    return text


@pytest.mark.parametrize("how", sorted(HOW))
@pytest.mark.parametrize("name", ["serve", "fleet", "inject", "map", "demo"])
def test_a_long_running_command_stops_cleanly_on_a_signal(name, how, router, tmp_path):
    argv, running, closed = _command(name, router, tmp_path)
    sig = HOW[how]
    with tempfile.TemporaryFile("w+b") as log:  # a file, never a pipe nobody reads
        proc = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", *argv],
            cwd=ROOT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            process_group=0,
        )

        def out() -> str:
            log.seek(0)
            return log.read().decode(errors="replace")

        try:
            _wait_for(
                lambda: running in out() or proc.poll() is not None,
                START_WITHIN_S,
                lambda: f"pfp {name} did not start:\n{out()[-3000:]}",
            )
            assert proc.poll() is None, f"pfp {name} ended by itself:\n{out()[-3000:]}"
            text = _stop_and_judge(proc, sig, out)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    assert closed in text, f"pfp {name} did not close what it opened:\n{text[-3000:]}"


@pytest.mark.parametrize("how", sorted(HOW))
def test_handheld_stops_cleanly_on_a_signal(how, router):
    pytest.importorskip("textual")
    import fcntl
    import termios

    sig = HOW[how]
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 60, 0, 0))
    proc = subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "handheld", "--unit", "hh-sig", "--connect", router]
        + ["--mission", "sig"],
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1", "TERM": "xterm-256color"},
        stdin=slave,
        stdout=slave,
        stderr=slave,
        process_group=0,
    )
    os.close(slave)
    screen = Output()

    def read() -> None:
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # the child closed its side
                return
            if not data:
                return
            screen.add(data.decode(errors="replace"))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        _wait_for(
            lambda: "hh-sig" in screen.text or proc.poll() is not None,
            START_WITHIN_S,
            lambda: f"pfp handheld did not draw:\n{screen.text[-3000:]}",
        )
        assert proc.poll() is None, f"pfp handheld ended by itself:\n{screen.text[-3000:]}"
        _stop_and_judge(proc, sig, lambda: screen.text)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        reader.join(timeout=5)
        os.close(master)
