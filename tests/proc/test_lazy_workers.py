"""Worker pools whose slots start on first use (``WorkerPool(eager=...)``): an idle planner holds fewer processes."""

from __future__ import annotations

import math
import queue
import time

import pytest

from pfp_service.node.tasks import Outcome, Task
from pfp_service.node.workers import WorkerPool


def _wait_for(cond, timeout_s: float = 60.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


@pytest.mark.proc
def test_lazy_slots_and_the_spare_start_with_the_first_task():
    pool = WorkerPool("t", 2, spare=True, eager=1)
    try:
        assert pool.wait_ready(60)  # ready once the eager slot is warm
        time.sleep(1.0)  # room for a lazy slot or the spare to start, if they wrongly would
        assert len(pool.pids()) == 1
        got: queue.Queue[Outcome] = queue.Queue()
        t0 = time.monotonic()
        pool.submit(Task(math.hypot, (3.0, 4.0), got.put, budget_s=5.0))
        out = got.get(timeout=60)
        assert out.kind == "done" and out.value == 5.0
        assert time.monotonic() - t0 < 5.0  # answered by the warm worker, not after another's warm-up
        _wait_for(lambda: len(pool.pids()) == 3)  # the second slot and the spare, now
    finally:
        pool.shutdown()


@pytest.mark.proc
def test_a_pool_with_no_eager_slot_is_ready_at_once_and_starts_on_its_first_task():
    pool = WorkerPool("t", 1, eager=0)
    try:
        assert pool.wait_ready(0.01)
        assert pool.pids() == []
        got: queue.Queue[Outcome] = queue.Queue()
        pool.submit(Task(math.sqrt, (16.0,), got.put, budget_s=60.0))
        assert got.get(timeout=120).value == 4.0
    finally:
        pool.shutdown()
