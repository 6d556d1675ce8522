"""Ctrl-C on ``pfp plan --planner optimal`` mid-grid ends it with 130: no core dump, no traceback.

The grid of ``--cells 2000`` takes its compiled kernels about 2 s and 2 GB to build.
Interrupted there, the command died of SIGSEGV (exit 139, -11 to Python) in 4 of 7
runs before ``signals.interruptible``: the ``KeyboardInterrupt`` was raised on the
thread that was returning from a kernel.  The SIGINT is sent once the process's
resident memory shows it inside the grid build (it only grows there), at two depths.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from tests.zenoh_util import ROOT

pytestmark = pytest.mark.proc

CAP_S = 60.0


def _rss_mb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads /proc")
@pytest.mark.parametrize("depth_mb", [900, 1600])
def test_ctrl_c_mid_grid_exits_130_without_a_crash_or_traceback(depth_mb: int) -> None:
    cmd = [sys.executable, "-X", "faulthandler", "-m", "pfp_service", "plan"]
    cmd += [str(ROOT / "examples" / "paper-simple.yaml"), "--planner", "optimal", "--cells", "2000"]
    proc = subprocess.Popen(
        cmd,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # a shell's background job ignores SIGINT, and a child inherits that: a terminal's Ctrl-C does not
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + CAP_S
        while proc.poll() is None and (_rss_mb(proc.pid) or 0.0) < depth_mb:
            assert time.monotonic() < deadline, f"the grid never reached {depth_mb} MB"
            time.sleep(0.01)
        assert proc.poll() is None, "the plan ended before it was interrupted: raise --cells"
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=CAP_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, f"exit {proc.returncode}: {err[-2000:]}"
    assert "Traceback" not in err and "Fatal Python error" not in err, err[-2000:]
