"""Live round trip: a unit's state put to the direction received, through the planner's embedded router.

Starts ``pfp serve`` as its own process on a free loopback port (the embedded
router), puts 8 threats and a goal, then times ``--count`` state → direction
round trips of one unit walking the route it is given (restarting on arrival), one at a time, from a client
session.  Reports the median, p90 and p99 against the 1 ms target.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any

from benchmarks._check import add_check_arg, exit_code
from pfp_service.argtypes import positive_int

TARGET_MEDIAN_MS = 1.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--count", type=positive_int, default=2000, help="round trips to time (default 2000)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_check_arg(p)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _client(endpoint: str) -> Any:
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    deadline = time.monotonic() + 20
    while True:
        try:
            return zenoh.open(conf)
        except Exception:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


def measure(count: int) -> dict[str, Any]:
    import msgspec

    from benchmarks.engine import table_threats
    from pfp_service.wire import Goal, ThreatUpdate, UnitState, decode_direction, encode, keys
    from pfp_service.wire.encoding import zenoh_encoding

    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    mission = "bench"
    state = tempfile.TemporaryDirectory(prefix="pfp-roundtrip-state-")  # never the user's state
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "pfp_service",
            "serve",
            "--listen",
            endpoint,
            "--mission",
            mission,
            "--log-level",
            "warning",
            "--state-dir",
            state.name,
        ],
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        session = _client(endpoint)
        try:
            got: queue.Queue[tuple[float, int | None, str, tuple[float, float]]] = queue.Queue()

            def on_direction(sample: Any) -> None:
                d = decode_direction(sample.payload.to_bytes())
                got.put((time.perf_counter(), d.seq, d.status.value, d.vector))

            sub = session.declare_subscriber(keys.unit_direction(mission, "u1"), on_direction)
            enc = zenoh_encoding()
            # wait for the planner: its status queryable answers
            deadline = time.monotonic() + 20
            while not any(r.ok for r in session.get(keys.planner_statuses(mission), timeout=1.0)):
                if time.monotonic() > deadline:
                    raise TimeoutError("planner did not start")
            for t in table_threats(30, 8):
                msg = ThreatUpdate(
                    position=t.xi, facing_deg=225.0, sigma_range=3.0, sigma_lateral=2.1, skew=2.0, weight=1.0
                )
                session.put(keys.threat(mission, t.id), encode(msg), encoding=enc)
            session.put(keys.unit_goal(mission, "u1"), encode(Goal(position=(30.0, 30.0))), encoding=enc)
            pub = session.declare_publisher(keys.unit_state(mission, "u1"), encoding=enc, express=True)
            time.sleep(0.5)
            samples = []
            x, y, step = 0.0, 0.0, 0.15
            for seq in range(count + 50):
                payload = encode(UnitState(position=(x, y), seq=seq))
                t0 = time.perf_counter()
                pub.put(payload)
                while True:
                    t1, dseq, status, vec = got.get(timeout=5.0)
                    if dseq == seq:
                        break
                if seq >= 50:  # warm-up excluded
                    samples.append((t1 - t0) * 1e3)
                if status in ("arrived", "trapped"):  # start the route again
                    x, y = 0.0, 0.0
                else:
                    x, y = x + step * vec[0], y + step * vec[1]
            sub.undeclare()
            pub.undeclare()
        finally:
            session.close()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
        state.cleanup()
    samples.sort()
    n = len(samples)
    return {
        "count": n,
        "threats": 8,
        "median_ms": statistics.median(samples),
        "p90_ms": samples[int(0.9 * (n - 1))],
        "p99_ms": samples[int(0.99 * (n - 1))],
        "target_median_ms": TARGET_MEDIAN_MS,
        "via": "embedded router (pfp serve subprocess), client session, tcp loopback",
        "encoder": msgspec.__version__,
    }


def run(args: argparse.Namespace) -> int:
    r = measure(args.count)
    ok = r["median_ms"] <= TARGET_MEDIAN_MS
    if args.json:
        print(json.dumps(r, indent=2))
        return exit_code([ok], args.check)
    print(f"pfp bench roundtrip: {r['count']} state -> direction round trips, 1 unit, 8 threats, {r['via']}")
    print(f"  median {r['median_ms']:.3f} ms, p90 {r['p90_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms")
    print(f"  [{'ok' if ok else 'MISSED'}] median <= {TARGET_MEDIAN_MS:g} ms")
    return exit_code([ok], args.check)
