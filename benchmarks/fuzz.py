"""Hostile input: malformed payloads on every key and queryable of a real planner, which must carry on.

Starts ``pfp serve`` as its own process on a free loopback port (JSON log to a
file), then sends ``--count`` malformed inputs on each of: unit states, goals,
threats (puts with congestion control BLOCK, so none is dropped on the way),
preview, status and world queries, plus unit and planner liveliness tokens
with odd ids.  The
inputs, from one seeded generator: random bytes, truncated JSON, deep nesting,
wrong types, NaN and Infinity, huge numbers, out-of-range values, bad UTF-8,
non-objects, impossible lat/lon positions (the planner has an origin), megabyte
payloads and valid payloads on keys with odd ids.

Then a bad unit sends poison goals (``POISON_GOALS``: valid JSON whose
numbers a planner once could not plan, a ZeroDivisionError or an
OverflowError inside it), each with every report for ``POISON_S`` seconds,
while ``INNOCENTS`` innocent units report at 10 Hz in the same ticks.

It passes when afterwards the planner
  - gives a fresh probe unit the same direction, bit for bit, as before the fuzz,
    and answered every probe sent during it within 5 s (no stall);
  - counted every put and delete as rejected (or as shed at its bounded inbox:
    ``overload``), and answered every query (an error reply that decodes, or a status);
  - grew its resident memory by at most ``--max-rss-growth-mb``;
  - answered at least ``INNOCENT_SHARE`` of the innocent units' reports beside the poison goals;
  - answered each preview bomb (``PREVIEW_BOMBS``, 3 at once) within 5 s, its process tree
    (workers included) back within 400 MB 8 s later, and a plain preview then planned within 3 s;
  - wrote zero tracebacks to its log, and is still running.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import random
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks._fuzz_bulkheads import (
    BOMB_GROWTH_MB,
    BOMB_PLAIN_S,
    BOMB_SETTLE_S,
    INNOCENT_SHARE,
    MISSION,
    POISON_GOALS,
    is_timeout,
    poison_goals,
    preview_bombs,
)
from pfp_service.argtypes import positive_float, positive_int

__all__ = ["CATEGORIES", "POISON_GOALS", "Input", "add_arguments", "fuzz", "malformed", "poison_goals", "run"]

from benchmarks._malformed import _ODD_IDS, CATEGORIES, ORIGIN, PROBE_TIMEOUT_S, Input, malformed


# -- the live run -------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--count", type=positive_int, default=10_000, help="inputs per key and queryable")
    p.add_argument("--seed", type=int, default=11, help="seed of the generator (default 11)")
    p.add_argument(
        "--max-rss-growth-mb", type=positive_float, default=100.0, help="memory bound (default 100 MB)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


class _Probe:
    """Fresh units asking the same question: from (0, 0) to (10, 10) among two threats, which way?"""

    def __init__(self, session: Any) -> None:
        from pfp_service.wire import keys

        self.s, self.n, self.keys = session, 0, keys
        self.latencies_ms: list[float] = []
        self.stalls = 0

    def ask(self) -> dict[str, Any] | None:
        import queue

        import zenoh

        from pfp_service.wire import decode_direction

        self.n += 1
        uid = f"probe{self.n}"
        got: queue.Queue[Any] = queue.Queue()
        sub = self.s.declare_subscriber(
            self.keys.unit_direction(MISSION, uid), lambda smp: got.put(smp.payload.to_bytes())
        )
        enc = zenoh.Encoding.APPLICATION_JSON
        try:
            self.s.put(self.keys.unit_goal(MISSION, uid), b'{"position": [10, 10]}', encoding=enc)
            t0 = time.perf_counter()
            deadline = time.monotonic() + PROBE_TIMEOUT_S
            seq = 0
            while time.monotonic() < deadline:  # the goal and the state race: report until en route
                seq += 1
                state = json.dumps({"position": [0.0, 0.0], "seq": seq}).encode()
                self.s.put(self.keys.unit_state(MISSION, uid), state, encoding=enc)
                try:
                    while True:
                        d = decode_direction(got.get(timeout=max(deadline - time.monotonic(), 0.01)))
                        if d.seq == seq:
                            break
                except queue.Empty:
                    break
                if d.status.value != "no_goal":
                    self.latencies_ms.append((time.perf_counter() - t0) * 1e3)
                    return {"status": d.status.value, "vector": list(d.vector), "level": d.threat_level}
            self.stalls += 1
            return None
        finally:
            sub.undeclare()
            self.s.delete(self.keys.unit_goal(MISSION, uid))


def _status(session: Any) -> Any:
    from pfp_service.wire import decode_planner_status, keys

    for r in session.get(keys.planner_statuses(MISSION), timeout=2.0):
        if r.ok is not None:
            return decode_planner_status(r.ok.payload.to_bytes())
    return None


def fuzz(count: int, seed: int, max_rss_growth_mb: float = 100.0, say: Callable[[str], None] = print) -> dict:
    """Run the whole fuzz against a fresh ``pfp serve`` subprocess; return the figures and ``ok``."""
    import zenoh

    from pfp_service.wire import keys

    rng = random.Random(seed)
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    log = tempfile.NamedTemporaryFile(prefix="pfp-fuzz-", suffix=".log", delete=False)  # noqa: SIM115
    # an origin, so {lat, lon} positions go the whole way through the geodetic path
    argv = ["serve", "--listen", endpoint, "--mission", MISSION, "--log-format", "json", "--origin", ORIGIN]
    state = tempfile.TemporaryDirectory(prefix="pfp-fuzz-state-")  # never the user's state
    argv += ["--state-dir", state.name]
    proc = subprocess.Popen(
        [sys.executable, "-m", "pfp_service", *argv],
        stdout=log,
        stderr=subprocess.STDOUT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    enc = zenoh.Encoding.APPLICATION_JSON
    block = zenoh.CongestionControl.BLOCK
    sent: Counter[str] = Counter()
    categories: Counter[str] = Counter()
    queries = {"sent": 0, "error_replies": 0, "unanswered": 0, "undecodable": 0}
    queries |= {f"{t}_replies": 0 for t in _REPLY_DECODERS}
    r: dict[str, Any] = {"count_per_target": count, "seed": seed}
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                session = zenoh.open(conf)
                if _status(session) is not None:
                    break
                session.close()
            except Exception:
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError("the planner did not start") from None
            time.sleep(0.2)
        try:
            for tid, pos in (("e1", [4, 6]), ("e2", [7, 3])):
                threat = {"position": pos, "facing_deg": 225, "sigma_range": 1.0, "sigma_lateral": 0.7}
                session.put(keys.threat(MISSION, tid), json.dumps(threat).encode(), encoding=enc)
            # the probe's goal and the threats travel on different keys: ask only once both threats
            # are in the world, or the first answer may be the threat-free one
            ready = time.monotonic() + 10.0
            while time.monotonic() < ready:
                st = _status(session)
                if st is not None and st.threats >= 2:
                    break
                time.sleep(0.05)
            probe = _Probe(session)
            before = probe.ask()
            rss0 = _rss_mb(proc.pid)
            rss_peak = rss0 or 0.0
            st0 = _status(session)
            rejected0, overload0 = st0.rejected, st0.overload
            say(f"pfp bench fuzz: seed {seed}, {count} inputs per target, planner pid {proc.pid}")
            t_start = time.perf_counter()
            for target, kind, make_key in (
                ("unit_state", "unit_state", lambda i: keys.unit_state(MISSION, f"fz{i}")),
                ("goal", "goal", lambda i: keys.unit_goal(MISSION, f"fz{i}")),
                ("threat", "threat", lambda i: keys.threat(MISSION, f"fz{i}")),
            ):
                for i in range(count):
                    x = malformed(rng, kind)
                    key = make_key(i) if x.odd_id is None else _odd_key(target, x.odd_id)
                    try:
                        session.put(key, x.payload, encoding=enc, congestion_control=block)
                    except zenoh.ZError:  # a key Zenoh itself refuses never reaches the planner
                        sent["refused_by_zenoh"] += 1
                        continue
                    sent[target] += 1
                    categories[x.category] += 1
                    if i % 1000 == 999:
                        probe.ask()
                        rss_peak = max(rss_peak, _rss_mb(proc.pid) or 0.0)
                say(f"  {target}: {count} puts sent")
            deletes = max(count // 10, 10)
            for i in range(deletes):
                target = ("goal", "threat")[i % 2]
                try:
                    session.delete(_odd_key(target, _ODD_IDS[i % len(_ODD_IDS)] + str(i)))
                except zenoh.ZError:
                    sent["refused_by_zenoh"] += 1
                    continue
                sent[f"{target}_delete"] += 1
            say(f"  goal, threat: {deletes} deletes with odd ids sent")
            for target in _REPLY_DECODERS:
                pending: list[Any] = []
                for i in range(count):
                    if target == "preview":
                        x = malformed(rng, "preview")
                        key = (
                            keys.preview(MISSION, f"fz{i}")
                            if x.odd_id is None
                            else _odd_key("preview", x.odd_id)
                        )
                        sel, payload = key, x.payload
                        categories[x.category] += 1
                    else:  # status or world: the planner's own key, any selector and body
                        own = keys.planner_status if target == "status" else keys.world
                        sel = own(MISSION, "planner") + rng.choice(
                            ["", "?a=b", "?;;;", "?" + "x" * 2000, "?max_iter=1e99"]
                        )
                        payload = malformed(rng, "preview").payload
                    pending.append(session.get(sel, payload=payload, timeout=10.0))
                    queries["sent"] += 1
                    if len(pending) >= 64 or i == count - 1:
                        for handler in pending:
                            _collect(handler, target, queries)
                        pending.clear()
                    if i % 1000 == 999:
                        probe.ask()
                        rss_peak = max(rss_peak, _rss_mb(proc.pid) or 0.0)
                say(f"  {target}: {count} queries sent")
            tokens = max(count // 10, 10)
            for i in range(tokens):  # unit and planner tokens: the planner watches both
                odd = _ODD_IDS[i % len(_ODD_IDS)] + str(i)
                kind = ("alive_unit", "alive_planner")[i % 2]
                tok = session.liveliness().declare_token(_odd_key(kind, odd))
                tok.undeclare()
                sent[kind] += 1
            say(f"  liveliness: {tokens} unit and planner tokens with odd ids declared and dropped")
            r["fuzz_s"] = round(time.perf_counter() - t_start, 1)
            # let the planner drain: the rejected counter stops moving
            expected = sum(sent[k] for k in ("unit_state", "goal", "threat", "goal_delete", "threat_delete"))
            # inputs the planner shed at its bounded inbox count as overload, not as rejected
            last, shed, still = -1, 0, time.monotonic()
            while time.monotonic() - still < 2.0 and time.monotonic() - t_start < 600:
                st = _status(session)
                now_rej = st.rejected - rejected0 if st is not None else -1
                shed = st.overload - overload0 if st is not None else shed
                if now_rej != last:
                    last, still = now_rej, time.monotonic()
                if now_rej + shed >= expected:
                    break
                time.sleep(0.2)
            after = probe.ask()
            rss1 = _rss_mb(proc.pid)
            r["poison_goals"] = poison_goals(session, say)  # after the count of rejections: it adds its own
            r["preview_bombs"] = preview_bombs(session, proc.pid, say)
            st1 = _status(session)
            r["faults"] = st1.faults if st1 is not None else None
            r.update(
                inputs=sum(sent.values()) + queries["sent"],
                puts=dict(sent),
                categories=dict(categories),
                queries=queries,
                rejected=last,
                shed_overload=shed,
                rejected_expected=expected,
                probe_before=before,
                probe_after=after,
                probes=probe.n,
                probe_stalls=probe.stalls,
                probe_p50_ms=_q(probe.latencies_ms, 0.5),
                probe_max_ms=max(probe.latencies_ms, default=None),
                rss_mb_before=rss0,
                rss_mb_peak=round(max(rss_peak, rss1 or 0.0), 1),
                rss_mb_after=rss1,
            )
        finally:
            session.close()
        r["planner_alive"] = proc.poll() is None
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()
        state.cleanup()
    text = Path(log.name).read_text(errors="replace")
    r["log_lines"] = text.count("\n")
    r["log_bytes"] = len(text)
    r["tracebacks"] = text.count("Traceback")
    r["log"] = log.name
    growth = (r["rss_mb_after"] - r["rss_mb_before"]) if r.get("rss_mb_before") else 0.0
    r["checks"] = {
        "same direction after the fuzz": r["probe_before"] is not None
        and r["probe_after"] == r["probe_before"],
        "no probe stalled (5 s)": r["probe_stalls"] == 0,
        "every put and delete rejected (or shed as overload)": r["rejected"] + r["shed_overload"]
        == r["rejected_expected"],
        "every query answered": queries["unanswered"] == 0 and queries["undecodable"] == 0,
        f"innocent units answered >= {INNOCENT_SHARE:.0%} beside poison goals": r["poison_goals"][
            "innocent_share"
        ]
        >= INNOCENT_SHARE,
        f"memory growth <= {max_rss_growth_mb:g} MB": growth <= max_rss_growth_mb,
        "every preview bomb answered within 5 s": r["preview_bombs"]["answered_in_time"],
        f"the planner's tree within {BOMB_GROWTH_MB:g} MB {BOMB_SETTLE_S:g} s after the bombs": r[
            "preview_bombs"
        ]["pss_mb_after"]
        - r["preview_bombs"]["pss_mb_before"]
        <= BOMB_GROWTH_MB,
        f"a plain preview planned within {BOMB_PLAIN_S:g} s after the bombs": r["preview_bombs"][
            "plain_after"
        ]["kind"]
        == "plan"
        and r["preview_bombs"]["plain_after"]["s"] <= BOMB_PLAIN_S,
        "zero tracebacks in the log": r["tracebacks"] == 0,
        "planner still running": r["planner_alive"],
    }
    r["ok"] = all(r["checks"].values())
    if r["tracebacks"] == 0:
        os.unlink(log.name)
        r["log"] = None
    return r


def _odd_key(target: str, odd: str) -> str:
    """A key of the layout with an id that ``keys`` would refuse to build, so it is spelled from its template."""
    from pfp_service.wire import keys

    kind = {"unit_state": keys.KeyKind.UNIT_STATE, "goal": keys.KeyKind.UNIT_GOAL}.get(target)
    kind = kind or {"threat": keys.KeyKind.THREAT, "preview": keys.KeyKind.PREVIEW}.get(target)
    kind = kind or {"alive_planner": keys.KeyKind.ALIVE_PLANNER}.get(target, keys.KeyKind.ALIVE_UNIT)
    return keys.TEMPLATES[kind].format(mission=MISSION, id=odd)


# The queryables fuzzed, and the decoder of each one's replies: its module and its name.
_REPLY_DECODERS: dict[str, tuple[str, str]] = {
    "preview": ("pfp_service.world.translate", "decode_plan_result"),
    "status": ("pfp_service.wire", "decode_planner_status"),
    "world": ("pfp_service.wire", "decode_world_snapshot"),
}


def _collect(handler: Any, target: str, queries: dict[str, int]) -> None:
    """Count one query's answers: a reply that decodes as ``target``'s, or an error reply that decodes."""
    from pfp_service import wire
    from pfp_service.errors import InputError

    replies = list(handler)
    good = [rep for rep in replies if rep.ok is not None or not is_timeout(rep)]
    if not good:
        queries["unanswered"] += 1
        return
    for rep in good:
        try:
            if rep.ok is not None:
                module, name = _REPLY_DECODERS[target]
                getattr(importlib.import_module(module), name)(rep.ok.payload.to_bytes())
                queries[f"{target}_replies"] += 1
            else:
                wire.decode_error_reply(rep.err.payload.to_bytes())
                queries["error_replies"] += 1
                queries[f"{target}_error_replies"] = queries.get(f"{target}_error_replies", 0) + 1
        except InputError:
            queries["undecodable"] += 1


def _q(xs: list[float], q: float) -> float | None:
    if not xs:
        return None
    s = sorted(xs)
    return round(s[min(len(s) - 1, int(q * len(s)))], 2)


def run(args: argparse.Namespace) -> int:
    r = fuzz(args.count, args.seed, args.max_rss_growth_mb, say=(lambda _: None) if args.json else print)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0 if r["ok"] else 1
    q = r["queries"]
    print(f"  inputs: {r['inputs']} in {r['fuzz_s']} s; by category: {r['categories']}")
    print(
        f"  rejected {r['rejected']} of {r['rejected_expected']} puts and deletes "
        f"({r['shed_overload']} more shed at the planner's bounded inbox); queries: {q}"
    )
    print(
        f"  probes: {r['probes']}, p50 {r['probe_p50_ms']} ms, max {r['probe_max_ms']} ms, "
        f"stalls {r['probe_stalls']}; direction before {r['probe_before']}, after {r['probe_after']}"
    )
    print(
        f"  planner RSS: {r['rss_mb_before']:.1f} MB before, {r['rss_mb_peak']:.1f} peak, "
        f"{r['rss_mb_after']:.1f} after; log {r['log_lines']} lines, {r['log_bytes']} bytes, "
        f"{r['tracebacks']} tracebacks"
    )
    pg = r["poison_goals"]
    print(
        f"  poison goals: innocent units answered {pg['innocent_share']:.1%} of their reports "
        f"({pg['baseline_share']:.1%} with no poison); faults inside the planner {r['faults']}"
    )
    for name, ok in r["checks"].items():
        print(f"  [{'ok' if ok else 'FAILED'}] {name}")
    if r["log"]:
        print(f"  the planner's log is kept at {r['log']}")
    return 0 if r["ok"] else 1
