"""The deliberation queue holds at most about twice the jobs still wanted, however many were cancelled."""

from __future__ import annotations

import heapq

import pytest

from pfp_service.node import deliberation
from pfp_service.node.deliberation import SWEEP_MIN, Deliberators
from pfp_service.world.events import Job

pytestmark = pytest.mark.unit


def _job(unit: int, version: int, kind: str = "foresee") -> Job:
    return Job(f"u{unit}", (0, version), kind, None, None, 1e9)  # type: ignore[arg-type]


def test_waves_of_superseded_jobs_do_not_grow_the_queue() -> None:
    d = Deliberators(1, lambda: 0.0, lambda _done: None)  # no job is fed: no worker starts
    try:
        units, waiting = 300, []
        for wave in range(40):  # each wave supersedes every unit's job while the worker is behind
            d.cancel(waiting)
            waiting = [_job(u, wave, "escape" if u % 7 == 0 else "foresee") for u in range(units)]
            d.submit(waiting)
            held = len(d._waiting)
            assert held <= units + max(SWEEP_MIN, held // 2) + 1
        assert len(d._waiting) < 3 * units  # without the sweep: 12,000
        live = []
        while d._waiting:
            job = heapq.heappop(d._waiting)[2]
            if not job.cancelled:
                live.append(job)
        assert live == sorted(waiting, key=lambda j: (deliberation._PRIORITY[j.kind], int(j.unit[1:])))
    finally:
        d.shutdown()
