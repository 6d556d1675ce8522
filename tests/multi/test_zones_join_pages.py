"""More keep-out zones than one world reply holds reach a joining planner, and the counts say so.

A router in the test process, planners as subprocesses (tier multi): nine
detailed zones (~100 KB of JSON each) put on planner A take several pages of
its world reply; planner B, started after, pages through them all
(``zones_from``/``next_zone``) and its status counts nine.  A killed and
restarted A says in its ``restored`` event how many zones it restored.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
import uuid

import pytest
import zenoh

from pfp_service.node.worldpages import whole_world
from pfp_service.wire import decode_event, decode_planner_status, decode_world_snapshot, keys
from tests.multi.test_zones_durable import _planner, _router, _stop
from tests.zenoh_util import client, free_port, put_in_force

pytestmark = pytest.mark.multi

N = 9


def _detailed(cx: float, cy: float, vertices: int = 3000, r: float = 40.0) -> dict[str, object]:
    ring = [
        [
            round(cx + r * math.cos(2 * math.pi * k / vertices), 6),
            round(cy + r * math.sin(2 * math.pi * k / vertices), 6),
        ]
        for k in range(vertices)
    ]
    return {"polygon": [[*ring, ring[0]]]}


def _zones_counted(s: zenoh.Session, mission: str, pid: str, want: int, timeout: float = 90.0) -> None:
    """Wait until planner ``pid``'s status counts ``want`` zones."""
    deadline = time.monotonic() + timeout
    seen = None
    while time.monotonic() < deadline:
        for r in s.get(keys.planner_status(mission, pid), timeout=2.0):
            if r.ok is not None:
                seen = decode_planner_status(r.ok.payload.to_bytes()).zones
                if seen == want:
                    return
        time.sleep(0.2)
    raise AssertionError(f"planner {pid} counts {seen} zones, not {want}")


def _whole(s: zenoh.Session, mission: str, pid: str):  # type: ignore[no-untyped-def]
    def ask(selector: str, timeout_s: float) -> list[bytes]:
        return [r.ok.payload.to_bytes() for r in s.get(selector, timeout=timeout_s) if r.ok is not None]

    (first,) = [decode_world_snapshot(b) for b in ask(keys.world(mission, pid), 5.0)]
    return first, whole_world(ask, mission, first, page_timeout_s=5.0)


def test_a_joining_planner_takes_more_zones_than_one_page_and_a_restart_counts_them(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    m = "zj" + uuid.uuid4().hex[:8]
    zones = {f"z{j}": _detailed(1000.0 + 200.0 * j, 2000.0) for j in range(N - 1)}
    zones["pond"] = {"circle": {"centre": [20, 60], "radius_m": 6}, "ttl_s": 3600}
    procs: list[subprocess.Popen[str]] = []
    with _router(endpoint), client(endpoint) as s:
        try:
            a = _planner(endpoint, m, "pa", str(tmp_path / "a"))
            procs.append(a)
            _zones_counted(s, m, "pa", 0)
            put_in_force(s, m, {keys.zone(m, z): body for z, body in zones.items()}, timeout=60.0)
            _zones_counted(s, m, "pa", N)
            first, (held, complete) = _whole(s, m, "pa")
            assert len(first.zones) < N and first.next_zone is not None  # it takes more than one page
            assert complete and sorted(z.id for z in held.zones) == sorted(zones)

            b = _planner(endpoint, m, "pb", str(tmp_path / "b"))  # joins: pages through pa's world
            procs.append(b)
            _zones_counted(s, m, "pb", N)
            _, (joined, complete) = _whole(s, m, "pb")
            assert complete and {z.id: z.zone.polygon for z in joined.zones} == {
                z.id: z.zone.polygon for z in held.zones
            }  # every vertex came
            (pond,) = [z for z in joined.zones if z.id == "pond"]
            assert pond.ttl_s is not None and 3000 < pond.ttl_s <= 3600  # the time left, not afresh

            got: list[bytes] = []
            sub = s.declare_subscriber(
                keys.event(m, "restored"), lambda smp: got.append(smp.payload.to_bytes())
            )
            try:
                a.send_signal(signal.SIGKILL)
                a.wait(timeout=10)
                _stop(b)  # nothing to join from: pa holds its own state
                a = _planner(endpoint, m, "pa", str(tmp_path / "a"))
                procs.append(a)
                _zones_counted(s, m, "pa", N)
                deadline = time.monotonic() + 30
                while not got and time.monotonic() < deadline:
                    time.sleep(0.1)
            finally:
                sub.undeclare()
            assert got, "no restored event"
            ev = decode_event(got[0])
            assert json.loads(got[0])["kind"] == "restored" and ev.zones == N  # type: ignore[attr-defined]
        finally:
            for p in procs:
                _stop(p)
