"""Preview storm: many mixed preview queries at once, while a live unit's directions are timed.

Starts ``pfp serve`` in its own process on a free loopback port, guides one
live unit through a field of threats, then fires ``--queries`` preview
queries from ``--threads`` threads, each with its own ``--timeout-s``: a mix
of schema-valid heavy what-ifs (50 threats of about 1 mm, a tiny step and a
huge ``max_iter``), garbage bodies, deep nesting and plain previews.  All the
while the live unit reports at ``--rate-hz`` and every answer's latency is
recorded.

It reports how many queries were answered (a reply or an error) within their
timeout, the answer times, and the live stream's p50/p99/max before and
during the storm.  It passes when every query is answered in time and the
live p99 during the storm is at most ``--max-p99-ms``.
"""

from __future__ import annotations

import argparse
import functools
import json
import threading
import time
from typing import Any

from pfp_service.bench._load import MISSION, start_server
from pfp_service.bench.roundtrip import _client
from pfp_service.cli._common import positive_float, positive_int
from pfp_service.wire import keys

__all__ = ["add_arguments", "run", "storm"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--queries", type=positive_int, default=250, help="preview queries in the storm (default: 250)"
    )
    p.add_argument("--threads", type=positive_int, default=25, help="threads sending them (default: 25)")
    p.add_argument(
        "--timeout-s", type=positive_float, default=10.0, help="each query's timeout (default: 10)"
    )
    p.add_argument(
        "--rate-hz", type=positive_float, default=20.0, help="the live unit's report rate (default: 20)"
    )
    p.add_argument("--max-p99-ms", type=positive_float, default=10.0, help="live p99 to pass (default: 10)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def _bodies() -> list[bytes | None]:
    heavy = {
        "goal": [5000.0, 5000.0],
        "step": 0.001,
        "max_iter": 10_000_000,
        "threats": [
            {"id": f"w{i}", "position": [10.0 * i, 20.0 * i], "sigma_range": 0.001, "sigma_lateral": 0.0015}
            for i in range(50)
        ],
    }
    return [
        json.dumps(heavy).encode(),
        b"\x00\xffnot json at all",
        b"[" * 100_000,
        json.dumps({"max_iter": 10_000_000, "step": 0.0005}).encode(),
        None,  # the live preview
    ]


def _quantiles(xs: list[float]) -> dict[str, float | None]:
    if not xs:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    s = sorted(xs)
    return {
        "n": len(s),
        "p50_ms": 1e3 * s[len(s) // 2],
        "p99_ms": 1e3 * s[min(len(s) - 1, int(0.99 * len(s)))],
        "max_ms": 1e3 * s[-1],
    }


def storm(queries: int, threads: int, timeout_s: float, rate_hz: float) -> dict[str, Any]:
    """Run the storm against a fresh planner; return the figures."""
    server = start_server("planner")
    figures: dict[str, Any] = {}
    try:
        with _client(server.endpoint) as session:
            figures = _storm(session, queries, threads, timeout_s, rate_hz)
    finally:
        figures["planner"] = server.stop()
    return figures


def _storm(session: Any, queries: int, threads: int, timeout_s: float, rate_hz: float) -> dict[str, Any]:
    m, unit = MISSION, "live-1"
    got: dict[int, float] = {}
    vec: dict[int, tuple[float, float]] = {}
    cond = threading.Condition()

    def on_direction(sample: Any) -> None:
        d = json.loads(sample.payload.to_bytes())
        seq = d.get("seq")
        with cond:
            got.setdefault(seq, time.monotonic())
            vec[seq] = (d["vector"][0], d["vector"][1])
            cond.notify_all()

    deadline = time.monotonic() + 120
    while not any(r.ok is not None for r in session.get(keys.planner_statuses(m), timeout=1.0)):
        if time.monotonic() > deadline:
            raise RuntimeError("the planner never answered its status")
        time.sleep(0.2)
    sub = session.declare_subscriber(keys.unit_direction(m, unit), on_direction)
    for i, pos in enumerate([(40.0, 60.0), (70.0, 30.0), (50.0, 50.0)]):
        threat = {"position": list(pos), "sigma_range": 10.0, "sigma_lateral": 7.0, "facing_deg": 225.0}
        session.put(keys.threat(m, f"t{i}"), json.dumps(threat))
    session.put(keys.unit_goal(m, unit), json.dumps({"position": [100.0, 100.0]}))
    sent: dict[int, float] = {}
    stop = threading.Event()
    phase = {"name": "before"}
    lat: dict[str, list[float]] = {"before": [], "during": []}
    unanswered = {"before": 0, "during": 0}

    def live() -> None:
        seq, x, y = 0, 0.0, 0.0
        while not stop.is_set():
            seq += 1
            now = time.monotonic()
            sent[seq] = now
            session.put(keys.unit_state(m, unit), json.dumps({"position": [x, y], "seq": seq}))
            answered = functools.partial(dict.__contains__, got, seq)
            with cond:
                cond.wait_for(answered, timeout=2.0)
            name = phase["name"]
            if seq in got:
                lat[name].append(got[seq] - sent[seq])
                x, y = x + 0.5 * vec[seq][0], y + 0.5 * vec[seq][1]  # it moves along what it is told
            else:
                unanswered[name] += 1
            time.sleep(max(0.0, 1.0 / rate_hz - (time.monotonic() - now)))

    t_live = threading.Thread(target=live, daemon=True)
    t_live.start()
    time.sleep(3.0)  # the live stream's own baseline
    bodies = _bodies()
    answers: list[tuple[float, str]] = []
    lock = threading.Lock()
    todo = list(range(queries))

    def asker() -> None:
        while True:
            with lock:
                if not todo:
                    return
                k = todo.pop()
            t0 = time.monotonic()
            replies = list(
                session.get(keys.preview(m, unit), payload=bodies[k % len(bodies)], timeout=timeout_s)
            )
            took = time.monotonic() - t0
            kind = "none"
            if replies:
                r = replies[0]
                kind = "reply" if r.ok is not None else "error"
                if kind == "error" and r.err is not None and b"Timeout" in r.err.payload.to_bytes():
                    kind = "timeout"
            with lock:
                answers.append((took, kind))

    phase["name"] = "during"
    t0 = time.monotonic()
    askers = [threading.Thread(target=asker, daemon=True) for _ in range(threads)]
    for t in askers:
        t.start()
    for t in askers:
        t.join(timeout=timeout_s * queries)
    storm_s = time.monotonic() - t0
    stop.set()
    t_live.join(timeout=5.0)
    sub.undeclare()
    in_time = sum(1 for took, kind in answers if kind in ("reply", "error") and took <= timeout_s)
    kinds: dict[str, int] = {}
    for _, kind in answers:
        kinds[kind] = kinds.get(kind, 0) + 1
    return {
        "queries": queries,
        "answered_in_time": in_time,
        "answers": kinds,
        "answer_time": _quantiles([took for took, _ in answers]),
        "storm_s": storm_s,
        "live_before": _quantiles(lat["before"]) | {"unanswered": unanswered["before"]},
        "live_during": _quantiles(lat["during"]) | {"unanswered": unanswered["during"]},
    }


def run(args: argparse.Namespace) -> int:
    figures = storm(args.queries, args.threads, args.timeout_s, args.rate_hz)
    live = figures["live_during"]
    ok = figures["answered_in_time"] == figures["queries"] and (live["p99_ms"] or 0.0) <= args.max_p99_ms
    figures["pass"] = ok
    if args.json:
        print(json.dumps(figures, indent=2))
    else:
        a = figures["answer_time"]
        print(f"previews: {figures['answered_in_time']}/{figures['queries']} answered within {args.timeout_s:g} s "
              f"({figures['answers']}); answer p50 {a['p50_ms']:.0f} ms, max {a['max_ms']:.0f} ms")  # fmt: skip
        for name in ("live_before", "live_during"):
            q = figures[name]
            if q["n"]:
                print(f"{name.replace('_', ' ')}: p50 {q['p50_ms']:.2f} ms  p99 {q['p99_ms']:.2f} ms  "
                      f"max {q['max_ms']:.2f} ms  ({q['n']} answered, {q['unanswered']} not)")  # fmt: skip
        print("PASS" if ok else "FAIL")
    return 0 if ok else 1
