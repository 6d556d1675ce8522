"""Failover: several ``--cluster`` planners share a fleet; kill one, again and again, and time the takeover.

Starts a Python router on a free loopback port and ``--planners`` planner
processes with ``--cluster``, then ``--units`` units that report in rounds
(every ``--round-s``) and record which planner answered.  Each of ``--kills``
times it SIGKILLs one planner, measures how long until every unit that
planner owned is answered by another, checks that no unit is then answered by
two planners, and starts a replacement.  It reports the failover times as a
distribution, and how evenly the units were shared.
"""

from __future__ import annotations

import argparse
import collections
import json
import signal
import subprocess
import sys
import threading
import time
from typing import Any

from benchmarks.roundtrip import _free_port
from pfp_service.argtypes import positive_float, positive_int
from pfp_service.wire import keys

__all__ = ["add_arguments", "failover", "run"]

MISSION = "failover"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--planners", type=positive_int, default=3, help="planner processes (default: 3)")
    p.add_argument("--units", type=positive_int, default=90, help="units sharing them (default: 90)")
    p.add_argument(
        "--kills", type=positive_int, default=5, help="planners killed, one at a time (default: 5)"
    )
    p.add_argument(
        "--round-s", type=positive_float, default=0.2, help="seconds between report rounds (default: 0.2)"
    )
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def _planner(endpoint: str, pid: str) -> subprocess.Popen[bytes]:
    cmd = [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint]
    cmd += [
        "--mission",
        MISSION,
        "--planner-id",
        pid,
        "--cluster",
        "--state-dir",
        "none",
        "--log-level",
        "error",
    ]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def failover(planners: int, units: int, kills: int, round_s: float) -> dict[str, Any]:
    """Run the kills; return the figures."""
    import zenoh

    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    procs: dict[str, subprocess.Popen[bytes]] = {}
    answered: dict[int, dict[str, set[str]]] = collections.defaultdict(lambda: collections.defaultdict(set))
    lock = threading.Lock()

    def on_direction(sample: Any) -> None:
        d = json.loads(sample.payload.to_bytes())
        with lock:
            answered[d.get("seq") or 0][d["unit"]].add(d.get("planner") or "?")

    with zenoh.open(conf) as session:
        try:
            for k in range(planners):
                procs[f"p{k}"] = _planner(endpoint, f"p{k}")
            deadline = time.monotonic() + 120
            while (
                len(
                    {
                        str(r.ok.key_expr)
                        for r in session.get(keys.planner_statuses(MISSION), timeout=1.0)
                        if r.ok
                    }
                )
                < planners
            ):
                if time.monotonic() > deadline:
                    raise RuntimeError("the planners never all answered")
                time.sleep(0.2)
            sub = session.declare_subscriber(keys.unit_directions(MISSION), on_direction)
            ids = [f"u{i:04d}" for i in range(units)]
            for u in ids:
                session.put(keys.unit_goal(MISSION, u), json.dumps({"position": [1000.0, 1000.0]}))
            seq = 0

            def round_() -> dict[str, set[str]]:
                nonlocal seq
                seq += 1
                for i, u in enumerate(ids):
                    session.put(
                        keys.shard_state(MISSION, u), json.dumps({"position": [i % 10, i // 10], "seq": seq})
                    )
                time.sleep(round_s)
                with lock:
                    return dict(answered.pop(seq, {}))

            def owners(n: int = 5) -> dict[str, set[str]]:
                merged: dict[str, set[str]] = collections.defaultdict(set)
                for _ in range(n):
                    for u, p in round_().items():
                        merged[u] |= p
                return merged

            times: list[float] = []
            doubled = 0
            shares: list[list[int]] = []
            next_id = planners
            for _ in range(kills):
                before = owners()
                shares.append(
                    sorted(
                        collections.Counter(next(iter(p)) for p in before.values() if len(p) == 1).values()
                    )
                )
                victim = sorted(procs)[0]
                theirs = {u for u, p in before.items() if p == {victim}}
                procs.pop(victim).send_signal(signal.SIGKILL)
                killed = time.monotonic()
                taken: set[str] = set()
                while taken != theirs and time.monotonic() - killed < 30:
                    for u, p in round_().items():
                        if u in theirs and p - {victim}:
                            taken.add(u)
                times.append(time.monotonic() - killed if taken == theirs else float("inf"))
                after = owners()
                doubled += sum(1 for p in after.values() if len(p) > 1)
                pid = f"p{next_id}"
                next_id += 1
                procs[pid] = _planner(endpoint, pid)
                deadline = time.monotonic() + 120
                while not any(r.ok for r in session.get(keys.planner_status(MISSION, pid), timeout=1.0)):
                    if time.monotonic() > deadline:
                        raise RuntimeError(f"replacement {pid} never answered")
                    time.sleep(0.2)
                time.sleep(1.0)  # let the newcomer take its share
            sub.undeclare()
        finally:
            for proc in procs.values():
                proc.kill()
                proc.wait()
    s = sorted(times)
    return {
        "planners": planners,
        "units": units,
        "kills": kills,
        "round_s": round_s,
        "failover_s": s,
        "failover_p50_s": s[len(s) // 2] if s else None,
        "failover_max_s": s[-1] if s else None,
        "answered_by_two_after_settling": doubled,
        "units_per_planner_before_each_kill": shares,
    }


def run(args: argparse.Namespace) -> int:
    r = failover(args.planners, args.units, args.kills, args.round_s)
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        times = ", ".join(f"{t:.2f}" for t in r["failover_s"])
        print(
            f"failover of {r['kills']} planners ({r['planners']} running, {r['units']} units, rounds {r['round_s']:g} s):"
        )
        print(f"  takeover s: {times}; p50 {r['failover_p50_s']:.2f} s, max {r['failover_max_s']:.2f} s")
        print(f"  units answered by two planners once settled: {r['answered_by_two_after_settling']}")
        print(f"  units per planner before each kill: {r['units_per_planner_before_each_kill']}")
    ok = (
        r["failover_max_s"] is not None
        and r["failover_max_s"] < 30
        and r["answered_by_two_after_settling"] == 0
    )
    return 0 if ok else 1
