"""Workers forked from a fork server (``forkserver.ForkServer``): cheap in memory, quick to start, still contained."""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest

from tests.zenoh_util import client, planner_process

ROOT = pathlib.Path(__file__).resolve().parents[2]

# a planner stand-in: it forks the fork server, runs a pool on it, reports, then waits to be killed
_SCRIPT = r"""
import gc, json, math, queue, sys, time
from pfp_service.node.forkserver import ForkServer, install_fork_server
from pfp_service.node.tasks import Task
from pfp_service.node.workers import WorkerPool

gc.freeze()
server = ForkServer.start()
assert server is not None, "no fork server in a process with one thread"
install_fork_server(server)
pool = WorkerPool("t", 2, spare=True, memory_mb=256.0, nice=3, eager=1)
assert pool.wait_ready(30)

def run(fn, args, budget_s=5.0):
    got = queue.Queue()
    t0 = time.monotonic()
    pool.submit(Task(fn, args, got.put, budget_s=budget_s))
    out = got.get(timeout=60)
    return out.kind, out.value, time.monotonic() - t0

report = {"fork_server": server.pid, "first": run(math.hypot, (3.0, 4.0))}
deadline = time.monotonic() + 30
while len(pool.pids()) < 3 and time.monotonic() < deadline:  # the second slot and the spare
    time.sleep(0.02)
report["pids"] = pool.pids()
report["killed"] = run(time.sleep, (30.0,), budget_s=0.2)[0]
report["memory"] = run(bytearray, (1 << 31,))[0]
report["after"] = run(math.hypot, (6.0, 8.0))
report["replaced"] = pool.replaced
deadline = time.monotonic() + 30
while (pool.ready_slots() < 2 or len(pool.pids()) < 3) and time.monotonic() < deadline:
    time.sleep(0.02)  # the replacements ready (niced and capped before they say so), and a new spare
report["live"] = pool.pids()
print(json.dumps(report), flush=True)
time.sleep(600)
"""


def _stat(pid: int) -> list[str]:
    return pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


def _alive(pid: int) -> bool:
    try:
        return _stat(pid)[0] != "Z"
    except OSError:
        return False


def _descendants(pid: int) -> set[int]:
    out: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        for task in pathlib.Path(f"/proc/{p}/task").glob("*/children"):
            with contextlib.suppress(OSError):
                kids = [int(c) for c in task.read_text().split()]
                out.update(kids)
                todo += kids
    return {p for p in out if _alive(p)}


def _gone_within(pids: set[int], timeout_s: float) -> tuple[float, list[int]]:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s and any(_alive(p) for p in pids):
        time.sleep(0.02)
    left = [p for p in pids if _alive(p)]
    for p in left:  # never leave them behind, whatever the verdict
        with contextlib.suppress(OSError):
            os.kill(p, signal.SIGKILL)
    return time.monotonic() - t0, left


@pytest.mark.proc
def test_forked_workers_keep_their_limits_are_replaced_and_die_with_their_planner():
    proc = subprocess.Popen(
        [sys.executable, "-c", _SCRIPT], cwd=ROOT, stdout=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line, f"the script ended: {proc.wait(timeout=10)}"
        report = json.loads(line)
        fork_server = report["fork_server"]
        kind, value, _ = report["first"]
        assert (kind, value) == ("done", 5.0)
        assert len(report["pids"]) == 3, report
        for pid in report[
            "live"
        ]:  # forked by the fork server (the replacements too), at the pool's priority and address-space cap
            assert int(_stat(pid)[1]) == fork_server
            assert int(_stat(pid)[16]) == 3  # nice
            limits = pathlib.Path(f"/proc/{pid}/limits").read_text()
            cap = next(x for x in limits.splitlines() if x.startswith("Max address space"))
            assert "unlimited" not in cap, cap
        assert report["killed"] == "killed" and report["memory"] == "memory"
        assert report["after"][:2] == ["done", 10.0] and report["replaced"] == 2
        tree = _descendants(proc.pid)
        assert fork_server in tree and set(report["live"]) <= tree
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        took, left = _gone_within(tree, 10.0)
        assert not left, f"still running after their planner was killed: {left}"
        assert took < 3.0, took  # a lifeline's end of file, not a poll: ~0 s on a quiet machine
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.proc
def test_pfp_serve_forks_its_workers_from_a_fork_server_and_they_die_with_it():
    from pfp_service.wire import keys

    with planner_process("--state-dir", "none", mission="forkserver") as (endpoint, proc):
        kids = _descendants(proc.pid)
        direct = {p for p in kids if int(_stat(p)[1]) == proc.pid}
        assert len(direct) == 1, kids  # the fork server only: no worker is a fresh interpreter
        (fork_server,) = direct
        assert b"workerproc" not in pathlib.Path(f"/proc/{fork_server}/cmdline").read_bytes()
        assert len(kids - direct) == 1, kids  # the one eager preview worker, forked by it
        with client(endpoint) as s:
            t0 = time.monotonic()
            replies = list(
                s.get(
                    keys.preview("forkserver", "u1"),
                    payload=b'{"start": [0, 0], "goal": [50, 0]}',
                    timeout=20,
                )
            )
            took = time.monotonic() - t0
        assert replies and replies[0].ok is not None
        assert json.loads(replies[0].ok.payload.to_bytes())["status"] == "reached"
        assert took < 5.0, took
        deadline = time.monotonic() + 30
        while len(_descendants(proc.pid)) < 4 and time.monotonic() < deadline:
            time.sleep(0.05)  # the second preview worker and the spare start with the first preview
        tree = _descendants(proc.pid)
        assert len(tree) >= 4, tree
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        took, left = _gone_within(tree, 10.0)
        assert not left, f"still running after their planner was killed: {left}"
        assert took < 3.0, took
