"""The tests' own planner start (``tests.zenoh_util``): a planner that exits before it answers fails at once.

Without this a planner that could not start (its port taken by another run's
planner, a flag refused) was waited for until ``wait_for_planner``'s 180 s
ran out, and the failure said only that it did not answer.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time

import pytest

from tests.zenoh_util import PlannerExited, free_port, wait_for_planner

pytestmark = pytest.mark.proc


def test_a_planner_that_exits_before_it_answers_fails_at_once_with_its_output():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with tempfile.TemporaryFile("w+") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", "serve", "--listen", endpoint, "--no-such-flag"],
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
        )
        t0 = time.monotonic()
        with pytest.raises(PlannerExited) as got:
            wait_for_planner(endpoint, "nobody", timeout=60.0, proc=proc, log=log)
        assert time.monotonic() - t0 < 30.0
        proc.wait(timeout=10)
    assert "exited with 2" in str(got.value) and "--no-such-flag" in str(got.value)
