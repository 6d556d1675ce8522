"""The phases of ``pfp bench service``: steady load, goal storm, contingency fan-out, the rate search.

Each phase drives a ``LoadGen`` against a ``Server`` and returns one dict of
figures.  Latency is a state's put to the first direction carrying its
``seq`` (seqs are unique over a run); a direction repeating a seq already
answered is a push.  Nothing is analysed while load runs.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from benchmarks._load import MISSION, Cluster, LoadGen, ProcMeter, Received, Server

__all__ = ["Bar", "RateSearch", "fanout", "forget", "register", "steady", "storm"]

STEP_M = 1.0  # a unit's move per report, and its goal's step, so stall detection sees honest motion
BYSTANDER_HZ = 50.0
LIVE_HZ = 1.0  # how often every unit reports through the storm and the fan-out, as in the issue
STORM_CAP_S = 15.0
FANOUT_CAP_S = 5.0
MAX_P99_MS = 10.0  # --find-max: the highest rate meeting both
MAX_UNANSWERED = 0.001


def _quantiles(ms: list[float]) -> dict[str, float | None]:
    if not ms:
        return {"p50_ms": None, "p90_ms": None, "p99_ms": None, "max_ms": None}
    a = np.asarray(ms)
    p50, p90, p99 = np.percentile(a, [50, 90, 99])
    return {"p50_ms": float(p50), "p90_ms": float(p90), "p99_ms": float(p99), "max_ms": float(a.max())}


def latency(g: LoadGen, seqs: range | list[int], recv: list[Received]) -> dict[str, Any]:
    """Answers to the states ``seqs``: latency, the unanswered fraction, and how many other directions came."""
    wanted = set(seqs)
    answered: dict[int, float] = {}
    others = 0
    for r in recv:
        if r.seq in wanted and r.seq not in answered:
            answered[r.seq] = r.t
        else:
            others += 1
    sent = len(wanted)
    ms = [1e3 * (t - g.sent[s]) for s, t in answered.items()]
    return {
        "sent": sent,
        "answered": len(answered),
        "unanswered_fraction": (sent - len(answered)) / sent if sent else 0.0,
        "other_directions": others,
        **_quantiles(ms),
    }


@contextmanager
def metered(g: LoadGen, srv: Server | Cluster) -> Iterator[dict[str, Any]]:
    """CPU % (responder and load generator), memory and the responder's own in/out counters over the block.

    ``loadavg`` (1 min, at the end) says how busy the shared machine was.
    """
    out: dict[str, Any] = {}
    me = ProcMeter(os.getpid(), tree=False)
    cpu0, gen0, st0, t0 = srv.meter.cpu_s(), me.cpu_s(), g.status(), time.perf_counter()
    yield out
    cpu1, gen1, st1, t1 = srv.meter.cpu_s(), me.cpu_s(), g.status(), time.perf_counter()
    wall = t1 - t0
    out["cpu_percent"] = None if cpu0 is None or cpu1 is None else 100 * (cpu1 - cpu0) / wall
    out["generator_cpu_percent"] = None if gen0 is None or gen1 is None else 100 * (gen1 - gen0) / wall
    out["loadavg"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    out.update(srv.meter.memory_mb())
    out["processes"] = srv.meter.processes()  # whose CPU cpu_percent counts: the responder and its workers
    if st0 is not None and st1 is not None:
        a, b = st0.get("msgs_in_each"), st1.get("msgs_in_each")
        if a and b:  # several planners: the states (and inputs) each applied, from its own counter
            out["server_msgs_in_each"] = {p: b[p] - a[p] for p in b if p in a and None not in (a[p], b[p])}
        out["server_msgs_in"] = st1["msgs_in"] - st0["msgs_in"]
        out["server_msgs_out"] = st1["msgs_out"] - st0["msgs_out"]
        out["server_overload"] = st1.get("overload", 0)
        out["server_deliberating"] = st1.get("deliberating", 0)
        out["server_latency_p99_ms"] = st1.get("latency_p99_ms")
        for k in ("pushes", "pushes_resent"):  # planners that count their pushes
            if k in st1 and k in st0:
                out[f"server_{k}"] = st1[k] - st0[k]


# -- phases ----------------------------------------------------------------------------------
def deliberations_landed(g: LoadGen, cap_s: float = 60.0) -> dict[str, Any]:
    """Wait until the planner has no deliberation pending (its status), at most ``cap_s``.

    The rate probes run after the storm's and fan-out's look-aheads have landed,
    so they measure the live loop, not the loop sharing the cores with leftover
    workers; ``landed`` false says they still ran (``left`` of them).
    """
    t0 = time.perf_counter()
    left: int | None = None
    while True:
        st = g.status(2.0)
        left = None if st is None else int(st.get("deliberating", 0))
        if left == 0 or time.perf_counter() - t0 >= cap_s:
            break
        time.sleep(0.2)
    return {"landed": left == 0, "left": left, "waited_s": time.perf_counter() - t0}


def register(g: LoadGen, n: int) -> int:
    """Every unit (and the bystander) reports once; returns how many were answered."""
    mark = len(g.recv)
    seqs = [g.send_state(g.ids[i], i) for i in range(n + 1)]
    g.settle(0.5, 10.0)
    got = {r.seq for r in g.recv[mark:]}
    return sum(1 for s in seqs if s in got)


def steady(
    g: LoadGen, srv: Server | Cluster, n: int, rate_hz: float, duration_s: float, bar: Bar, label: str
) -> dict[str, Any]:
    mark = len(g.recv)
    task = bar.task(f"{label}: {n} units x {rate_hz:g} Hz")
    with metered(g, srv) as meter:
        first, end, spent = g.pace(n * rate_hz, duration_s, list(range(n)), tick=task)
        g.settle()
    recv = g.recv[mark:]
    lat = latency(g, range(first, end), recv)
    if g.mixed:  # half the units on each key at once: each half's own figures, from the same moments
        halves: dict[str, list[int]] = {"shard": [], "plain": []}
        for seq in range(first, end):
            halves[g.key_of(g.seq_unit[seq])].append(seq)
        lat["by_key"] = {k: latency(g, seqs, recv) for k, seqs in halves.items()}
    last: dict[str, str] = {}
    by_seq: dict[int | None, set[str | None]] = {}
    by_unit: dict[str, set[str | None]] = {}
    for r in recv:
        last[r.unit] = r.status
        by_seq.setdefault(r.seq, set()).add(r.planner)
        by_unit.setdefault(r.unit, set()).add(r.planner)
    shares: dict[str, int] = {}
    for ps in by_unit.values():
        if len(ps) == 1:
            name = str(next(iter(ps)))
            shares[name] = shares.get(name, 0) + 1
    statuses: dict[str, int] = {}
    for s in last.values():
        statuses[s] = statuses.get(s, 0) + 1
    task(1.0)
    return {
        "units": n,
        "rate_hz": rate_hz,
        "offered_per_s": n * rate_hz,
        "spent_s": spent,
        "input_per_s": (end - first) / spent,
        "answered_per_s": lat["answered"] / spent,
        "output_per_s": len(recv) / spent,
        **lat,
        **meter,
        "statuses": statuses,
        # several planners (--planners): each state must be answered by one, each unit guided by one
        "answered_twice": sum(1 for s, ps in by_seq.items() if s is not None and len(ps) > 1),
        "units_answered_by_two": sum(1 for ps in by_unit.values() if len(ps) > 1),
        "units_per_planner": dict(sorted(shares.items())),
    }


class _Deliberation:
    """Per unit, from the directions as they come: first guided, deliberation begun and ended, route taken."""

    def __init__(self, g: LoadGen, units: set[str], mark: int) -> None:
        self.g, self.units, self.seen = g, units, mark
        self.guided: dict[str, float] = {}
        self.started: set[str] = set()
        self.ended: dict[str, float] = {}
        self.escaping: dict[str, float] = {}

    def scan(self) -> None:
        for r in self.g.recv[self.seen :]:
            if r.unit not in self.units or r.status == "no_goal":
                continue
            self.guided.setdefault(r.unit, r.t)
            if r.status == "escaping":
                self.escaping.setdefault(r.unit, r.t)
            if r.deliberating:
                self.started.add(r.unit)
            elif r.unit in self.started:
                self.ended.setdefault(r.unit, r.t)
        self.seen = len(self.g.recv)

    def all_ended(self) -> bool:
        return len(self.ended) == len(self.started)

    def figures(self, t0: float) -> dict[str, Any]:
        def last(d: dict[str, float], complete: bool) -> float | None:
            return max(d.values()) - t0 if d and complete else None

        def median(d: dict[str, float]) -> float | None:
            return float(np.median([t - t0 for t in d.values()])) if d else None

        return {
            "deliberations_started": len(self.started),
            "deliberations_ended": len(self.ended),
            "all_deliberated_s": last(self.ended, self.all_ended()),
            "deliberated_p50_s": median(self.ended),
            "routes_taken": len(self.escaping),  # units told ``escaping``: a committed escape route
            "last_route_s": last(self.escaping, True),
        }


def storm(g: LoadGen, srv: Server | Cluster, lay: dict[str, Any], n: int, bar: Bar) -> dict[str, Any]:
    """All goals at once while the units report at 1 Hz and a guided bystander (index n) at 50 Hz."""
    from pfp_service.wire import Goal, keys

    b, units = n, list(range(n))
    g.put_json(keys.unit_goal(MISSION, g.ids[b]), Goal(position=lay["goals"][b], step=STEP_M))
    g.pace(n * LIVE_HZ, 1.0, units, extra=(b, BYSTANDER_HZ))  # live, and the bystander guided and moving
    task = bar.task(f"goal storm: {n} goals at once")
    mark, first_seq = len(g.recv), g.seq
    watch = _Deliberation(g, set(g.ids[:n]), mark)

    def finished() -> bool:
        watch.scan()
        return len(watch.guided) == n and watch.all_ended()

    with metered(g, srv) as meter:
        t_goals = time.perf_counter()
        for i in units:
            g.put_json(keys.unit_goal(MISSION, g.ids[i]), Goal(position=lay["goals"][i], step=STEP_M))
        put_s = time.perf_counter() - t_goals
        g.pace(n * LIVE_HZ, STORM_CAP_S, units, tick=task, extra=(b, BYSTANDER_HZ), until=finished)
        end_seq = g.seq
        g.settle()
    watch.scan()
    recv = g.recv[mark:]
    seqs = range(first_seq, end_seq)
    by = latency(g, [s for s in seqs if g.seq_unit[s] == g.ids[b]], [r for r in recv if r.unit == g.ids[b]])
    fleet = latency(
        g, [s for s in seqs if g.seq_unit[s] != g.ids[b]], [r for r in recv if r.unit != g.ids[b]]
    )
    keep = ("sent", "unanswered_fraction", "p50_ms", "p99_ms", "max_ms")
    task(1.0)
    return {
        "goals": n,
        "put_all_s": put_s,
        "guided": len(watch.guided),
        "all_guided_s": max(watch.guided.values()) - t_goals if len(watch.guided) == n else None,
        "guided_p50_s": float(np.median([t - t_goals for t in watch.guided.values()]))
        if watch.guided
        else None,
        **watch.figures(t_goals),
        "window_s": time.perf_counter() - t_goals,
        "bystander": {k: by[k] for k in keep},
        "units_1hz": {k: fleet[k] for k in keep},
        **meter,
    }


def fanout(g: LoadGen, srv: Server | Cluster, n: int, bar: Bar) -> dict[str, Any]:
    """One threat just ahead of the live units' centre: the push wave, then their deliberations.

    The units go quiet for the wave, so every direction in it is a push and
    pushes sent (the responder's ``msgs_out`` less its events) compare with
    delivered; then they report at 1 Hz again until every deliberation the
    wave started has ended (a unit whose look-ahead changes nothing is told at
    its next report).
    """
    from pfp_service.wire import ThreatUpdate, keys

    everyone = list(range(n + 1))
    ids = set(g.ids)
    task = bar.task("contingency fan-out")
    g.pace((n + 1) * LIVE_HZ, 2.0, everyone)  # every unit live: reported within the last 2 s
    g.settle(0.3, 3.0)  # quiet: every answer is in
    pts = np.asarray(g.pos[:n])
    at = (float(np.median(pts[:, 0])) + 60.0, float(np.median(pts[:, 1])))
    threat = ThreatUpdate(position=at, facing_deg=270.0, sigma_range=40.0, sigma_lateral=28.0, skew=2.0)
    mark, ev_mark = len(g.recv), len(g.events)
    first: dict[str, float] = {}
    seen = mark
    affected: int | None = None
    with metered(g, srv) as wave:
        t_put = time.perf_counter()
        g.put_json(keys.threat(MISSION, "contingency"), threat)
        while time.perf_counter() < t_put + 1.0:
            time.sleep(0.005)
            for r in g.recv[seen:]:
                if r.unit in ids:
                    first.setdefault(r.unit, r.t)
            seen = len(g.recv)
            for _t, kind, doc in g.events[ev_mark:]:
                if kind == "replan" and affected is None:
                    affected = len(doc.get("units", [])) + int(doc.get("more_units", 0))
            if affected is not None and len(first) >= affected:
                break
        g.settle(0.6, 3.0)  # past the planner's re-sends of the pushes not yet answered
    task(0.2)
    pushes = [r for r in g.recv[mark:] if r.t >= t_put]
    for r in pushes:  # the units are quiet: every direction since the put is a push, re-sends too
        if r.unit in ids:
            first.setdefault(r.unit, r.t)
    for _t, kind, doc in g.events[ev_mark:]:  # a replan event later than the first second
        if kind == "replan" and affected is None:
            affected = len(doc.get("units", [])) + int(doc.get("more_units", 0))
    events = len(g.events) - ev_mark
    watch = _Deliberation(g, ids, mark)
    watch.scan()

    def finished() -> bool:
        watch.scan()
        return watch.all_ended()

    g.pace((n + 1) * LIVE_HZ, FANOUT_CAP_S, everyone, until=finished)
    watch.scan()
    task(1.0)
    told = sorted(t - t_put for t in first.values())
    complete = bool(told) and affected is not None and len(first) >= affected
    sent = wave.get("server_msgs_out")
    return {
        "live_units": n + 1,
        "threat_at": list(at),
        "affected": affected,
        "redirected": len(first),
        "all_redirected_ms": 1e3 * told[-1] if complete else None,
        "redirected_p50_ms": 1e3 * told[len(told) // 2] if told else None,
        **watch.figures(t_put),
        "pushes_sent": None if sent is None else sent - events,  # every copy, re-sends included
        "pushes_delivered": len(pushes),
        "pushes_first_copies": wave.get("server_pushes"),
        "pushes_resent": wave.get("server_pushes_resent"),
        "events_received": events,
        **wave,
    }


def forget(
    g: LoadGen, srv: Server | Cluster, bar: Bar, idle_rss_mb: float | None, cap_s: float
) -> dict[str, Any]:
    """Every unit goes quiet; wait until the planner holds none (stale, then forgotten), then read its RSS."""
    task = bar.task("units going stale and forgotten")
    before = srv.meter.memory_mb()["rss_mb"]
    t0 = time.perf_counter()
    units: int | None = None
    while time.perf_counter() < t0 + cap_s:
        st = g.status(2.0)
        units = None if st is None else int(st["units"])
        task(min((time.perf_counter() - t0) / cap_s, 1.0))
        if units == 0:
            break
        time.sleep(1.0)
    gone_s = time.perf_counter() - t0
    time.sleep(2.0)  # what the allocator gives back comes back soon or not at all
    after = srv.meter.memory_mb()["rss_mb"]
    task(1.0)
    return {
        "units_left": units,
        "all_forgotten_s": gone_s if units == 0 else None,
        "rss_before_mb": before,
        "rss_after_mb": after,
        "idle_rss_mb": idle_rss_mb,
        "after_vs_idle": None if after is None or not idle_rss_mb else after / idle_rss_mb,
    }


class RateSearch:
    """The highest per-unit rate whose probe passes (p99 ≤ 10 ms, ≤ 0.1 % unanswered): double, then bisect.

    One probe at a time, so two searches (planner and echo) can take turns and
    share the machine's noise.
    """

    KEEP = (
        "rate_hz",
        "offered_per_s",
        "input_per_s",
        "p50_ms",
        "p99_ms",
        "unanswered_fraction",
        "cpu_percent",
    )

    def __init__(self, start_hz: float, max_probes: int = 10) -> None:
        self.rate: float | None = start_hz
        self.lo: float | None = None
        self.hi: float | None = None
        self.left = max_probes
        self.short = 0
        self.probes: list[dict[str, Any]] = []
        self.before: dict[str, Any] = {}  # whether the planner's deliberations had landed first

    def record(self, r: dict[str, Any]) -> None:
        """Judge one ``steady`` result at ``self.rate`` and choose the next rate (``None``: done)."""
        rate = r["rate_hz"]
        ok = (
            r["p99_ms"] is not None
            and r["p99_ms"] <= MAX_P99_MS
            and r["unanswered_fraction"] <= MAX_UNANSWERED
        )
        # fewer states went out than offered: the responder's back-pressure (puts BLOCK) or the generator's CPU
        short = r["sent"] < 0.9 * r["offered_per_s"] * r["spent_s"] - 2
        self.short += short
        extra = {"deliberating_after": r.get("server_deliberating"), "processes": r.get("processes")}
        self.probes.append({k: r[k] for k in self.KEEP} | extra | {"ok": ok and not short})
        if ok and not short:
            self.lo = rate
        else:
            self.hi = rate
        self.left -= 1
        nxt: float | None
        if self.lo is not None and self.hi is not None:
            nxt = None if self.hi / self.lo < 1.15 else (self.lo + self.hi) / 2
        elif self.lo is None:
            nxt = rate / 2 if rate / 2 >= 0.05 else None
        else:
            nxt = rate * 2
        self.rate = nxt if self.left > 0 else None

    def result(self, n: int) -> dict[str, Any]:
        return self.before | {
            "max_rate_hz": self.lo,
            "max_per_s": None if self.lo is None else self.lo * n,
            "short_probes": self.short,
            "probes": self.probes,
        }


# -- progress ---------------------------------------------------------------------------------
class Bar:
    """A rich progress bar on stderr when it is a terminal; nothing otherwise."""

    def __init__(self) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        console = Console(stderr=True)
        self._p = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TimeElapsedColumn(),
            console=console,
            disable=not console.is_terminal,
            refresh_per_second=4,
        )

    def __enter__(self) -> Bar:
        self._p.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._p.stop()

    def task(self, description: str) -> Callable[[float], None]:
        """A new bar; call the returned function with the fraction done."""
        tid = self._p.add_task(description, total=1.0)
        return lambda frac: self._p.update(tid, completed=frac)


# -- the run ----------------------------------------------------------------------------------
