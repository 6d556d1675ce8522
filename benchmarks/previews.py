"""Previews under attack and under load: bombs, what-if bursts and mixed storms, while a live unit is timed.

Each scenario starts ``pfp serve`` (its defaults) in its own process on a free
loopback port, guides one probe unit that reports at ``--rate-hz`` and times
every direction it gets back (its baseline first, then while the scenario
runs), and sends preview queries from many threads at once:

* ``bombs``: ``--live-threats`` (2,000) threats in force, then 3 heavy
  previews at once (start ``[-900, -900]``, goal ``[1e9, 1e9]``, step 1e-3,
  ``max_iter`` 1e7, 256 what-ifs, half of them with sigma 1e6).  It measures
  when each is answered, the planner's process tree (every process, its
  workers included: PSS from ``/proc/*/smaps_rollup``) before and
  ``--settle-s`` (8 s) after, and then how long a plain preview takes to
  get a plan.  Passes: each answered within 5 s, the tree grown by at most
  400 MB, the plain preview planned within 3 s.
* ``whatifs``: 50 threats in force, then ``--burst`` (100) light what-ifs at
  once (one what-if threat each, goal 800 m away).  Passes: every one answered
  within 5 s, at least 80 % with a plan, the probe's p99 at most
  ``--max-p99-ms`` (50) while they run.
* ``storm``: ``--queries`` mixed queries (heavy what-ifs, garbage bodies, deep
  nesting, plain previews) from ``--threads`` threads, each with its own
  ``--timeout-s``.  Passes: every one answered in time, the probe's p99 at
  most ``--max-p99-ms``.
"""

from __future__ import annotations

import argparse
import json
import random
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from benchmarks._check import add_check_arg
from benchmarks._load import MISSION, start_server
from benchmarks._procs import tree_pss_mb
from benchmarks.roundtrip import _client
from pfp_service.argtypes import positive_float, positive_int
from pfp_service.wire import keys

__all__ = [
    "SCENARIOS",
    "add_arguments",
    "bombs",
    "run",
    "storm",
    "whatifs",
]

PROBE = "live-1"
ANSWER_S = 5.0  # the bars: every preview answered within this
PLAIN_PLAN_S = 3.0  # after the bombs, a plain preview gets a plan within this
MAX_GROWTH_MB = 400.0  # after the bombs, the planner's process tree grew by at most this
PLAN_SHARE = 0.8  # of a what-if burst, at least this share get a plan


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--scenario",
        choices=[*SCENARIOS, "all"],
        action="append",
        help="run this scenario (repeatable; default: bombs and whatifs)",
    )
    p.add_argument(
        "--live-threats",
        type=positive_int,
        default=2000,
        help="threats in force for the bombs (default: 2000)",
    )
    p.add_argument(
        "--settle-s", type=positive_float, default=8.0, help="bombs: memory measured this long after"
    )
    p.add_argument("--burst", type=positive_int, default=100, help="whatifs: previews at once (default: 100)")
    p.add_argument("--queries", type=positive_int, default=250, help="storm: queries (default: 250)")
    p.add_argument(
        "--threads", type=positive_int, default=25, help="storm: threads sending them (default: 25)"
    )
    p.add_argument("--timeout-s", type=positive_float, default=10.0, help="storm: each query's timeout")
    p.add_argument(
        "--rate-hz", type=positive_float, default=10.0, help="the probe unit's report rate (default: 10)"
    )
    p.add_argument("--max-p99-ms", type=positive_float, default=50.0, help="probe p99 to pass (default: 50)")
    p.add_argument("--seed", type=int, default=1, help="threat positions (default: 1)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    add_check_arg(p)  # accepted for a uniform pipeline: previews exits 1 on FAIL with or without it


# -- measuring ------------------------------------------------------------------------
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


class _Probe:
    """A unit reporting at ``rate_hz`` that times each direction; ``phase`` names the window a sample goes to."""

    def __init__(self, session: Any, rate_hz: float, goal: tuple[float, float]) -> None:
        self.session, self.rate_hz = session, rate_hz
        self.phase = "warmup"  # its first second (the goal's first directions) counts nowhere
        self.lat: dict[str, list[float]] = {}
        self.unanswered: dict[str, int] = {}
        self._got: dict[int, tuple[float, tuple[float, float]]] = {}
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._sub = session.declare_subscriber(keys.unit_direction(MISSION, PROBE), self._on_direction)
        session.put(keys.unit_goal(MISSION, PROBE), json.dumps({"position": list(goal)}))
        self._thread = threading.Thread(target=self._run, name="probe", daemon=True)
        self._thread.start()

    def _on_direction(self, sample: Any) -> None:
        d = json.loads(sample.payload.to_bytes())
        with self._cond:
            self._got.setdefault(d.get("seq"), (time.monotonic(), (d["vector"][0], d["vector"][1])))
            self._cond.notify_all()

    def _run(self) -> None:
        seq, x, y = 0, 0.0, 0.0
        while not self._stop.is_set():
            seq += 1
            t0 = time.monotonic()
            self.session.put(keys.unit_state(MISSION, PROBE), json.dumps({"position": [x, y], "seq": seq}))
            with self._cond:
                self._cond.wait_for(lambda s=seq: s in self._got, timeout=2.0)  # type: ignore[misc]
                got = self._got.pop(seq, None)
            name = self.phase
            if got is not None:
                self.lat.setdefault(name, []).append(got[0] - t0)
                x, y = x + 0.2 * got[1][0], y + 0.2 * got[1][1]  # it moves along what it is told, slowly
            else:
                self.unanswered[name] = self.unanswered.get(name, 0) + 1
            time.sleep(max(0.0, 1.0 / self.rate_hz - (time.monotonic() - t0)))

    def figures(self, name: str) -> dict[str, Any]:
        return _quantiles(self.lat.get(name, [])) | {"unanswered": self.unanswered.get(name, 0)}

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._sub.undeclare()


def _query(session: Any, unit: str, body: bytes | None, timeout_s: float) -> tuple[float, str, str]:
    """One preview query: ``(seconds, kind, detail)``, kind ``plan``, ``error``, ``timeout`` or ``none``."""
    t0 = time.monotonic()
    replies = list(session.get(keys.preview(MISSION, unit), payload=body, timeout=timeout_s))
    took = time.monotonic() - t0
    if not replies:
        return took, "none", ""
    r = replies[0]
    if r.ok is not None:
        return took, "plan", json.loads(r.ok.payload.to_bytes()).get("status", "")
    text = r.err.payload.to_bytes().decode(errors="replace") if r.err is not None else ""
    if "Timeout" in text:
        return took, "timeout", ""
    try:
        return took, "error", str(json.loads(text).get("error", ""))[:60]
    except ValueError:
        return took, "error", text[:60]


def _burst(session: Any, bodies: list[bytes | None], timeout_s: float) -> list[tuple[float, str, str]]:
    """Every body as its own query, all at once (one thread each)."""
    out: list[tuple[float, str, str]] = []
    lock = threading.Lock()
    go = threading.Event()

    def one(body: bytes | None) -> None:
        go.wait()
        got = _query(session, PROBE, body, timeout_s)
        with lock:
            out.append(got)

    threads = [threading.Thread(target=one, args=(b,), daemon=True) for b in bodies]
    for t in threads:
        t.start()
    go.set()
    for t in threads:
        t.join(timeout=timeout_s + 30)
    return out


def _put_threats(session: Any, n: int, rng: random.Random) -> None:
    for i in range(n):
        threat = {
            "position": [rng.uniform(-1000, 1000), rng.uniform(-1000, 1000)],
            "sigma_range": 10.0,
            "sigma_lateral": 7.0,
            "facing_deg": rng.uniform(0, 360),
        }
        session.put(
            keys.threat(MISSION, f"t{i}"),
            json.dumps(threat),
            congestion_control=zenoh.CongestionControl.BLOCK,
        )


def _status(session: Any) -> dict[str, Any] | None:
    for r in session.get(keys.planner_statuses(MISSION), timeout=2.0):
        if r.ok is not None:
            return dict(json.loads(r.ok.payload.to_bytes()))
    return None


def _wait(what: str, cond: Callable[[], bool], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out waiting for {what}")
        time.sleep(0.2)


def _with_planner(body: Callable[[Any, Any], dict[str, Any]]) -> dict[str, Any]:
    server = start_server("planner")
    figures: dict[str, Any] = {}
    try:
        with _client(server.endpoint) as session:
            _wait("the planner's status", lambda: _status(session) is not None, 120.0)
            figures = body(session, server)
    finally:
        figures["planner"] = server.stop()
    return figures


def _kinds(answers: list[tuple[float, str, str]]) -> dict[str, int]:
    kinds: dict[str, int] = {}
    for _, kind, detail in answers:
        name = kind if kind != "error" else f"error: {detail.split(':')[0]}"
        kinds[name] = kinds.get(name, 0) + 1
    return kinds


# -- scenarios ------------------------------------------------------------------------
def heavy_body(rng: random.Random) -> bytes:
    """The issue's preview bomb: a goal 1e9 m away at 1 mm steps, 256 what-ifs, half of them a megametre wide."""
    threats = [
        {
            "id": f"b{i}",
            "position": [rng.uniform(-1000, 1000), rng.uniform(-1000, 1000)],
            "sigma_range": 1e6 if i % 2 else 5.0,
            "sigma_lateral": 1e6 if i % 2 else 3.0,
        }
        for i in range(256)
    ]
    body = {
        "start": [-900, -900],
        "goal": [1e9, 1e9],
        "step": 1e-3,
        "max_iter": 10_000_000,
        "threats": threats,
    }
    return json.dumps(body).encode()


def bombs(args: argparse.Namespace) -> dict[str, Any]:
    """3 preview bombs with ``--live-threats`` in force: answer times, memory growth, a plain preview after."""
    rng = random.Random(args.seed)

    def body(session: Any, server: Any) -> dict[str, Any]:
        _put_threats(session, args.live_threats, rng)
        _wait("the threats", lambda: (_status(session) or {}).get("threats") == args.live_threats, 120.0)
        probe = _Probe(session, args.rate_hz, (100.0, 100.0))
        try:
            time.sleep(1.0)
            probe.phase = "before"
            time.sleep(3.0)  # the probe's baseline, and the field shipped to the workers
            _query(session, PROBE, None, 10.0)  # the plain preview warm: what follows is the bombs' cost
            pss_before = tree_pss_mb(server.proc.pid)
            probe.phase = "during"
            t0 = time.monotonic()
            answers = _burst(session, [heavy_body(rng) for _ in range(3)], 10.0)
            peak = pss_before
            while time.monotonic() - t0 < args.settle_s:
                peak = max(peak, tree_pss_mb(server.proc.pid))
                time.sleep(0.25)
            pss_after = tree_pss_mb(server.proc.pid)
            plain = _query(session, PROBE, None, 10.0)
        finally:
            probe.close()
        return {
            "live_threats": args.live_threats,
            "answers": _kinds(answers),
            "answer_s": sorted(round(a[0], 3) for a in answers),
            "pss_before_mb": round(pss_before, 1),
            "pss_peak_mb": round(peak, 1),
            "pss_after_mb": round(pss_after, 1),
            "growth_mb": round(pss_after - pss_before, 1),
            "plain_after": {"s": round(plain[0], 3), "kind": plain[1], "status": plain[2]},
            "probe_before": probe.figures("before"),
            "probe_during": probe.figures("during"),
            "pass": all(a[1] in ("plan", "error") and a[0] <= ANSWER_S for a in answers)
            and pss_after - pss_before <= MAX_GROWTH_MB
            and plain[1] == "plan"
            and plain[0] <= PLAIN_PLAN_S,
        }

    return _with_planner(body)


def light_body(rng: random.Random, i: int) -> bytes:
    """A light what-if: one extra threat near the way to a goal 800 m away."""
    goal = [800 / 2**0.5, 800 / 2**0.5]
    t = rng.uniform(0.1, 0.9)
    threat = {
        "id": f"w{i}",
        "position": [goal[0] * t + rng.uniform(-30, 30), goal[1] * t + rng.uniform(-30, 30)],
        "sigma_range": 15.0,
        "sigma_lateral": 10.0,
    }
    return json.dumps({"start": [0.0, 0.0], "goal": goal, "threats": [threat]}).encode()


def whatifs(args: argparse.Namespace) -> dict[str, Any]:
    """``--burst`` light what-ifs at once with 50 threats in force; the probe timed before and during."""
    rng = random.Random(args.seed)

    def body(session: Any, server: Any) -> dict[str, Any]:
        _put_threats(session, 50, rng)
        _wait("the threats", lambda: (_status(session) or {}).get("threats") == 50, 60.0)
        probe = _Probe(session, args.rate_hz, (800.0, 800.0))
        try:
            time.sleep(1.0)
            probe.phase = "before"
            time.sleep(5.0)  # the probe's baseline
            probe.phase = "during"
            t0 = time.monotonic()
            answers = _burst(session, [light_body(rng, i) for i in range(args.burst)], 10.0)
            took = time.monotonic() - t0
            time.sleep(max(0.0, 5.0 - took))  # the probe through at least 5 s of it
        finally:
            probe.close()
        plans = sum(1 for a in answers if a[1] == "plan")
        during = probe.figures("during")
        return {
            "burst": args.burst,
            "answers": _kinds(answers),
            "answer_time": _quantiles([a[0] for a in answers]),
            "plans": plans,
            "burst_s": round(took, 3),
            "probe_before": probe.figures("before"),
            "probe_during": during,
            "pass": len(answers) == args.burst
            and all(a[1] in ("plan", "error") and a[0] <= ANSWER_S for a in answers)
            and plans >= PLAN_SHARE * args.burst
            and (during["p99_ms"] or 0.0) <= args.max_p99_ms,
        }

    return _with_planner(body)


def _storm_bodies() -> list[bytes | None]:
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


def storm(args: argparse.Namespace) -> dict[str, Any]:
    """``--queries`` mixed preview queries from ``--threads`` threads, with 3 threats in force."""

    def body(session: Any, server: Any) -> dict[str, Any]:
        for i, pos in enumerate([(40.0, 60.0), (70.0, 30.0), (50.0, 50.0)]):
            threat = {"position": list(pos), "sigma_range": 10.0, "sigma_lateral": 7.0, "facing_deg": 225.0}
            session.put(keys.threat(MISSION, f"t{i}"), json.dumps(threat))
        probe = _Probe(session, args.rate_hz, (100.0, 100.0))
        bodies = _storm_bodies()
        answers: list[tuple[float, str, str]] = []
        lock = threading.Lock()
        todo = list(range(args.queries))

        def asker() -> None:
            while True:
                with lock:
                    if not todo:
                        return
                    k = todo.pop()
                got = _query(session, PROBE, bodies[k % len(bodies)], args.timeout_s)
                with lock:
                    answers.append(got)

        try:
            time.sleep(1.0)
            probe.phase = "before"
            time.sleep(3.0)  # the probe's baseline
            probe.phase = "during"
            t0 = time.monotonic()
            askers = [threading.Thread(target=asker, daemon=True) for _ in range(args.threads)]
            for t in askers:
                t.start()
            for t in askers:
                t.join(timeout=args.timeout_s * args.queries)
            storm_s = time.monotonic() - t0
        finally:
            probe.close()
        in_time = sum(1 for took, kind, _ in answers if kind in ("plan", "error") and took <= args.timeout_s)
        during = probe.figures("during")
        return {
            "queries": args.queries,
            "answered_in_time": in_time,
            "answers": _kinds(answers),
            "answer_time": _quantiles([a[0] for a in answers]),
            "storm_s": storm_s,
            "probe_before": probe.figures("before"),
            "probe_during": during,
            "pass": in_time == args.queries and (during["p99_ms"] or 0.0) <= args.max_p99_ms,
        }

    return _with_planner(body)


SCENARIOS: dict[str, Callable[[argparse.Namespace], dict[str, Any]]] = {
    "bombs": bombs,
    "whatifs": whatifs,
    "storm": storm,
}


def _say(name: str, f: dict[str, Any]) -> None:
    print(f"{name}: {'PASS' if f.get('pass') else 'FAIL'}  answers {f.get('answers')}")
    if name == "bombs":
        print(f"  answered in {f['answer_s']} s; PSS {f['pss_before_mb']:.0f} -> {f['pss_after_mb']:.0f} MB "
              f"(growth {f['growth_mb']:.0f} MB, peak {f['pss_peak_mb']:.0f}); plain preview after: "
              f"{f['plain_after']['kind']} {f['plain_after']['status']} in {f['plain_after']['s']:.2f} s")  # fmt: skip
    elif "answer_time" in f:
        a = f["answer_time"]
        if a["n"]:
            print(f"  answer p50 {a['p50_ms']:.0f} ms, max {a['max_ms']:.0f} ms; plans {f.get('plans', '-')}")
    for phase in ("probe_before", "probe_during"):
        q = f.get(phase, {})
        if q.get("n"):
            print(f"  {phase.replace('_', ' ')}: p50 {q['p50_ms']:.2f} ms  p99 {q['p99_ms']:.2f} ms  "
                  f"max {q['max_ms']:.2f} ms  ({q['n']} answered, {q['unanswered']} not)")  # fmt: skip
    planner = f.get("planner", {})
    if planner.get("error_lines"):
        print(f"  planner log: {planner['error_lines']} error lines, first {planner['first_errors'][:2]}")


def run(args: argparse.Namespace) -> int:
    chosen = args.scenario or ["bombs", "whatifs"]
    names = list(SCENARIOS) if "all" in chosen else list(dict.fromkeys(chosen))
    figures = {name: SCENARIOS[name](args) for name in names}
    ok = all(f.get("pass") for f in figures.values())
    if args.json:
        print(json.dumps(figures | {"pass": ok}, indent=2))
    else:
        for name, f in figures.items():
            _say(name, f)
        print("PASS" if ok else "FAIL")
    return 0 if ok else 1
