"""Keep-out zones outlive their planner: restored after ``kill -9``, and taken by a planner that joins.

A router in the test process, planners as subprocesses (tier multi): a zone put
(acknowledged) on planner A is held by planner B started after it (B asks A's
world), and by A again after A is killed with SIGKILL and restarted on the same
state directory; a zone deleted before the kill stays deleted.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import uuid

import pytest
import zenoh

from pfp_service.wire import decode_world_snapshot, keys
from pfp_service.wire.delivery import Deliverer
from tests.zenoh_util import ROOT, client, free_port, put_in_force

pytestmark = pytest.mark.multi

WALL = {"polygon": [[[40, 5], [46, 5], [46, 35], [40, 35], [40, 5]]]}
POND = {"circle": {"centre": [20, 60], "radius_m": 6}, "ttl_s": 3600}


def _router(endpoint: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def _planner(endpoint: str, mission: str, pid: str, state: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint,
         "--mission", mission, "--planner-id", pid, "--cluster", "--state-dir", state],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip


def _zones_of(s: zenoh.Session, mission: str, pid: str, timeout: float = 90.0) -> dict[str, float | None]:
    """The zones planner ``pid`` holds (id -> TTL left), once it answers its world query."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for r in s.get(keys.world(mission, pid), timeout=2.0):
            if r.ok is not None:
                snap = decode_world_snapshot(r.ok.payload.to_bytes())
                return {z.id: z.ttl_s for z in snap.zones}
        time.sleep(0.2)
    raise AssertionError(f"planner {pid} never answered its world query")


def _stop(p: subprocess.Popen[str]) -> None:
    if p.poll() is None:
        p.terminate()
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def test_zones_survive_kill_9_and_a_joining_planner_takes_them(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    m = "zd" + uuid.uuid4().hex[:8]
    procs: list[subprocess.Popen[str]] = []
    with _router(endpoint), client(endpoint) as s:
        try:
            a = _planner(endpoint, m, "pa", str(tmp_path / "a"))
            procs.append(a)
            assert _zones_of(s, m, "pa") == {}
            put_in_force(
                s, m, {keys.zone(m, "wall"): WALL, keys.zone(m, "pond"): POND, keys.zone(m, "gone"): WALL}
            )
            with Deliverer(s, m) as d:  # an acknowledged delete
                d.delete(keys.zone(m, "gone"))
                assert d.wait_delivered(15)
            held = _zones_of(s, m, "pa")
            assert set(held) == {"wall", "pond"} and held["wall"] is None

            b = _planner(endpoint, m, "pb", str(tmp_path / "b"))  # joins: asks pa's world
            procs.append(b)
            joined = _zones_of(s, m, "pb")
            assert set(joined) == {"wall", "pond"}
            assert joined["pond"] is not None and 3000 < joined["pond"] <= 3600  # the time left, not afresh

            a.send_signal(signal.SIGKILL)
            a.wait(timeout=10)
            _stop(b)  # nothing to join from: what pa holds after the restart is its own state
            a = _planner(endpoint, m, "pa", str(tmp_path / "a"))
            procs.append(a)
            restored = _zones_of(s, m, "pa")
            assert set(restored) == {"wall", "pond"}, restored
            assert restored["pond"] is not None and restored["pond"] <= held["pond"]  # type: ignore[operator]
        finally:
            for p in procs:
                _stop(p)
