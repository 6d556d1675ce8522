"""The wave first, live: a threat re-directing many units sends each its direction, then the same with its points."""

from __future__ import annotations

import json
import os
import time

import pytest

from pfp_service.wire import keys
from pfp_service.world.world import WAVE_FIRST
from tests.zenoh_util import Inbox, client, guide_in_a_column, planner_process, put_in_force

pytestmark = pytest.mark.proc

N = WAVE_FIRST + 16


def _deliberations_landed(s, m: str, timeout: float = 90.0) -> None:
    """Wait until the planner has no look-ahead pending (its status), so none lands during the wave."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in s.get(f"mumt/{m}/planner/*/status", timeout=2.0):
            if reply.ok is not None and json.loads(reply.ok.payload.to_bytes())["deliberating"] == 0:
                return
        time.sleep(0.2)
    raise TimeoutError("the planner's deliberations did not land")


def test_a_wave_reaches_every_unit_first_and_its_points_follow():
    m = "wave" + str(os.getpid())
    ids = [f"u{i:03d}" for i in range(N)]
    with planner_process("--state-dir", "none", mission=m) as (endpoint, _proc), client(endpoint) as s:
        inbox = Inbox(s, f"mumt/{m}/unit/*/direction")
        put_in_force(s, m, {keys.unit_goal(m, u): {"position": [60.0, float(i)]} for i, u in enumerate(ids)})
        answered = guide_in_a_column(s, m, ids, inbox)  # every unit guided once
        assert answered == set(ids)
        _deliberations_landed(s, m)
        time.sleep(1.5)  # the units quiet, the re-sends of the routes that landed past
        while not inbox.q.empty():
            inbox.q.get()
        threat = {"position": [20.0, 40.0], "facing_deg": 270.0, "sigma_range": 4.0, "sigma_lateral": 3.0}
        put_in_force(s, m, {keys.threat(m, "c"): threat})
        first: dict[str, dict] = {}
        pointed: dict[str, dict] = {}
        deadline = time.monotonic() + 30
        while len(pointed) < len(first) or len(first) <= WAVE_FIRST:
            d = inbox.get(timeout=max(deadline - time.monotonic(), 0.01))
            first.setdefault(d["unit"], d)
            if d["lookahead"]:
                pointed.setdefault(d["unit"], d)
        wave = [u for u, d in first.items() if not d["lookahead"]]
        assert len(wave) > WAVE_FIRST  # the wave's directions went out without their points ...
        for u in wave:  # ... and each came again with them, the same direction
            assert pointed[u]["vector"] == first[u]["vector"] and pointed[u]["status"] == first[u]["status"]
