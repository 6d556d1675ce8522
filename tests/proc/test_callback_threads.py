"""A process that declared Zenoh callbacks on a daemon thread ends cleanly once it waits for their threads.

zenoh-python runs each plain-callable subscriber on a thread that inherits the
daemon flag of the thread that declared it (``pfp handheld`` declares on its
connecting thread, ``pfp demo`` on its fleet thread).  Closing the session
ends those threads, but one that takes the GIL back while the interpreter
finalises aborts the process ("FATAL: exception not rethrown", exit -6): a
fresh clone's CI run lost ``test_handheld_stops_cleanly_on_a_signal`` to it,
and the script below without the wait aborted in 13 of 40 runs on this
machine.  ``signals.settle_callback_threads`` is the wait ``pfp`` does before
its process finalises; here it must hold in every one of 20 runs, which the
script without it passes with a chance of about 0.7^20 (0.08 %).
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.zenoh_util import ROOT

pytestmark = pytest.mark.proc

RUNS = 20
SCRIPT = """
import threading, zenoh
from pfp_service.signals import settle_callback_threads
conf = zenoh.Config()
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("listen/endpoints", "[]")
box = {}
def declare():
    box["s"] = s = zenoh.open(conf)
    box["subs"] = [s.declare_subscriber(f"cb/{i}", lambda sample: None) for i in range(40)]
t = threading.Thread(target=declare, daemon=True)
t.start()
t.join()
assert all(th.daemon for th in threading.enumerate() if th.name.endswith("(pyo3-closure)"))
box["s"].close()
print("settled" if settle_callback_threads() else "not settled", flush=True)
"""


def test_a_closed_sessions_daemon_callback_threads_end_before_the_interpreter_does():
    for run in range(RUNS):
        done = subprocess.run(
            [sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 0, f"run {run}: exit {done.returncode}: {done.stderr[-2000:]}"
        assert done.stdout.strip() == "settled", f"run {run}: {done.stdout!r} {done.stderr[-2000:]}"


def test_an_open_sessions_callback_threads_do_not_hold_the_process():
    """A session left open: its threads never end; the wait says so within its bound instead of hanging."""
    script = SCRIPT.replace('box["s"].close()', "").replace(
        "settle_callback_threads()", "settle_callback_threads(0.5)"
    )
    script += "\nfrom pfp_service.signals import leave_now\nleave_now(3)\n"
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert (done.returncode, done.stdout.strip()) == (3, "not settled"), done.stderr[-2000:]
