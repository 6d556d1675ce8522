"""The parts of ``pfp bench service`` that touch processes and the wire: servers, meters, the load generator.

* ``start_server`` runs the responder in its own process on a free loopback
  port, in router mode: ``pfp serve`` (the planner) or ``echo_main`` (a
  trivial Python zenoh responder answering every state with a fixed
  direction, the transport's own ceiling).  ``start_cluster`` runs a plain
  router (``router_main``) and ``--cluster`` planners as its clients, for
  ``--planners``.
* ``ProcMeter`` (``_procs``) reads a process's CPU time and resident memory from ``/proc``.
* ``LoadGen`` is the load generator's client session: it paces unit states,
  moves each unit along the last vector it was given, and timestamps every
  direction that comes back.  Nothing is analysed while load runs; the
  callback decodes a few fields and appends, so the generator disturbs the
  measurement as little as it can.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

import msgspec

from benchmarks._procs import ProcMeter
from benchmarks.roundtrip import _client, _free_port

__all__ = [
    "Cluster",
    "LoadGen",
    "ProcMeter",
    "Received",
    "Server",
    "connected",
    "start_cluster",
    "start_server",
]

MISSION = "bench"
PLANNER_ID = "planner"


class _Dir(msgspec.Struct):
    """The fields of a direction the bench reads; msgspec skips the rest unparsed."""

    unit: str
    status: str
    seq: int | None = None
    vector: tuple[float, float] = (0.0, 0.0)
    deliberating: bool = False
    planner: str | None = None


_DIR = msgspec.json.Decoder(_Dir)
_SUMMED = ("msgs_in", "msgs_out", "overload", "deliberating", "pushes", "pushes_resent", "units_owned")
MOVING = ("en_route", "escaping")


class Received(msgspec.Struct, frozen=True, gc=False):
    """One direction as it arrived: local receipt time (``perf_counter``) and what the bench reads of it.

    Untracked by the cyclic collector (``gc=False``: its fields are atoms).  A run keeps one per
    direction, hundreds of thousands, and the collector's full passes over them stopped this process
    for up to 111 ms inside a measured window: no state sent, no receipt timed, then a burst of both
    (BENCHMARKS.md, "The load generator's own pauses").
    """

    t: float
    unit: str
    seq: int | None
    status: str
    deliberating: bool
    planner: str | None = None  # which planner sent it (several share a mission under --planners)


# -- servers ----------------------------------------------------------------------------
@dataclass
class Server:
    """A responder process on a loopback endpoint; ``log`` holds its stderr."""

    kind: str
    endpoint: str
    proc: subprocess.Popen[bytes]
    log: IO[bytes]
    meter: ProcMeter = field(init=False)

    def __post_init__(self) -> None:
        self.meter = ProcMeter(self.proc.pid)

    def stop(self) -> dict[str, Any]:
        """Terminate it; return its exit code and the error lines of its log."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.seek(0)
        text = self.log.read().decode(errors="replace")
        self.log.close()
        bad = [ln for ln in text.splitlines() if "Traceback" in ln or "error" in ln.lower()]
        return {"exit_code": self.proc.returncode, "error_lines": len(bad), "first_errors": bad[:5]}


def start_server(
    kind: str,
    escape: str | None = None,
    stale_s: float = 60.0,
    forget_s: float | None = None,
    connect: str | None = None,
    planner_id: str = PLANNER_ID,
    extra: tuple[str, ...] = (),
) -> Server:
    """Start ``kind`` (``planner``, ``echo`` or ``router``) in router mode on a free loopback port.

    The planner's ``unit_stale_s`` is ``stale_s`` (the bench's quiet windows must not make units
    stale) and its ``unit_forget_s`` is ``forget_s`` (``None``: its default).  With ``connect``
    the planner is instead a ``--cluster`` client of the router there, named ``planner_id``.
    ``extra``: more ``pfp serve`` flags (``--dispersion``).
    """
    endpoint = connect or f"tcp/127.0.0.1:{_free_port()}"
    if kind == "planner":
        cmd = [sys.executable, "-m", "pfp_service", "serve", "--mission", MISSION]
        if connect is None:
            cmd += ["--listen", endpoint]
        else:
            cmd += ["--mode", "client", "--connect", connect, "--cluster"]
        # no durable state between runs; units quiet through a storm or fan-out window stay live
        cmd += ["--planner-id", planner_id, "--log-level", "warning", "--state-dir", "none"]
        cmd += ["--unit-stale-s", f"{stale_s:g}"]
        if forget_s is not None:
            cmd += ["--unit-forget-s", f"{forget_s:g}"]
        if escape is not None:
            cmd += ["--escape", escape]
        cmd += list(extra)  # more of ``pfp serve``'s flags (``--terrain DEM``)
    else:
        main = "echo_main" if kind == "echo" else "router_main"
        code = f"import sys; from benchmarks._responders import {main}; {main}(sys.argv[1])"
        cmd = [sys.executable, "-c", code, endpoint]
    log = tempfile.TemporaryFile()  # noqa: SIM115 -- the Server owns it and closes it in stop()
    proc = subprocess.Popen(
        cmd, env={**os.environ, "PYTHONUNBUFFERED": "1"}, stdout=subprocess.DEVNULL, stderr=log
    )
    return Server(kind, endpoint, proc, log)


def connected(make: Any, cap_s: float = 30.0) -> LoadGen:
    """``make()`` once the router process listens (it starts in its own process: seconds on a loaded machine)."""
    t0 = time.perf_counter()
    while True:
        try:
            return make()  # type: ignore[no-any-return]
        except Exception:
            if time.perf_counter() - t0 > cap_s:
                raise
            time.sleep(0.3)


class _SumMeter:
    """``ProcMeter``'s figures summed over several processes (a cluster: its planners and its router)."""

    def __init__(self, meters: list[ProcMeter]) -> None:
        self.meters = meters

    def cpu_s(self) -> float | None:
        each = [m.cpu_s() for m in self.meters]
        return None if any(c is None for c in each) else sum(c for c in each if c is not None)

    def processes(self) -> int:
        return sum(m.processes() for m in self.meters)

    def memory_mb(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {"rss_mb": 0.0, "peak_rss_mb": 0.0}
        for m in self.meters:
            for k, v in m.memory_mb().items():
                out[k] = None if v is None or out[k] is None else out[k] + v  # type: ignore[operator]
        return out


@dataclass
class Cluster:
    """A router process and ``--cluster`` planners, its clients: one ``Server`` to the phases.

    ``meter`` sums CPU and memory over every process (planners and router), so a
    cluster's CPU is all it costs the machine.
    """

    router: Server
    planners: list[Server]
    kind: str = "cluster"
    meter: Any = field(init=False)

    def __post_init__(self) -> None:
        self.meter = _SumMeter([s.meter for s in (self.router, *self.planners)])

    @property
    def endpoint(self) -> str:
        return self.router.endpoint

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(cluster_ids(len(self.planners)))

    def stop(self) -> dict[str, Any]:
        """Stop the planners, then the router; their exit codes and error lines together."""
        each = [s.stop() for s in self.planners] + [self.router.stop()]
        return {
            "exit_code": next((e["exit_code"] for e in each if e["exit_code"]), 0),  # the first failure
            "error_lines": sum(e["error_lines"] for e in each),
            "first_errors": [ln for e in each for ln in e["first_errors"]][:5],
        }


def cluster_ids(k: int) -> list[str]:
    """The planner ids of a ``k``-planner cluster (the first is ``PLANNER_ID``)."""
    return [PLANNER_ID] + [f"{PLANNER_ID}-{i}" for i in range(1, k)]


def start_cluster(k: int, escape: str | None = None, stale_s: float = 60.0) -> Cluster:
    """A plain router on a free loopback port and ``k`` ``--cluster`` planners connected to it."""
    router = start_server("router")
    planners = [
        start_server("planner", escape, stale_s, connect=router.endpoint, planner_id=pid)
        for pid in cluster_ids(k)
    ]
    return Cluster(router, planners)


class LoadGen:
    """A client session acting as ``n`` units (``u0`` ...), plus anything else the bench puts.

    Args:
        endpoint: the responder's router.
        starts: each unit's first position, metres.
        step_m: how far a unit moves per report along its last vector (its goal's ``step``).
    """

    def __init__(
        self,
        endpoint: str,
        starts: list[tuple[float, float]],
        step_m: float,
        planners: tuple[str, ...] = (PLANNER_ID,),
    ) -> None:
        import zenoh

        from pfp_service.wire import encode, keys
        from pfp_service.wire.encoding import zenoh_encoding

        self._zenoh = zenoh
        self._encode = encode
        self._keys = keys
        self.session = _client(endpoint)
        self.enc = zenoh_encoding()
        self.ids = [f"u{i}" for i in range(len(starts))]
        self.index = {u: i for i, u in enumerate(self.ids)}
        self.pos = [list(p) for p in starts]
        self.vec: dict[str, tuple[float, float]] = {}
        self.step_m = step_m
        self.planners = planners
        self.seq = 0
        self._rr = 0  # where the round robin of ``pace`` goes on
        self.sent: dict[int, float] = {}  # seq -> perf_counter at the put; seq is unique over the run
        self.seq_unit: dict[int, str] = {}
        self.recv: list[Received] = []
        self.events: list[tuple[float, str, dict[str, Any]]] = []
        self.bad = 0
        # the key each state goes on: its shard (our clients) or the plain key (a client that does not shard)
        self._keys_by = {
            "shard": {u: zenoh.KeyExpr(keys.shard_state(MISSION, u)) for u in self.ids},
            "plain": {u: zenoh.KeyExpr(keys.unit_state(MISSION, u)) for u in self.ids},
        }
        # mixed: the even units on their shard key, the odd on the plain key (our fleet beside outside vehicles)
        self._keys_by["mixed"] = {
            u: self._keys_by["plain" if i % 2 else "shard"][u] for i, u in enumerate(self.ids)
        }
        self._state_keys = self._keys_by["shard"]
        self.mixed = False
        self._subs = [
            self.session.declare_subscriber(keys.unit_directions(MISSION), self._on_direction),
            self.session.declare_subscriber(keys.events(MISSION), self._on_event),
        ]

    def use_key(self, name: str) -> None:
        """Put the states that follow on ``name``'s key: ``shard`` (the default), ``plain`` or ``mixed``."""
        self._state_keys = self._keys_by[name]
        self.mixed = name == "mixed"

    def key_of(self, unit: str) -> str:
        """Which key ``unit``'s states go on now: ``shard`` or ``plain``."""
        return "plain" if str(self._state_keys[unit]) == str(self._keys_by["plain"][unit]) else "shard"

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
        self.session.close()

    # callbacks: decode a few fields and append, nothing more
    def _on_direction(self, sample: Any) -> None:
        t = time.perf_counter()
        try:
            d = _DIR.decode(sample.payload.to_bytes())
        except msgspec.DecodeError:
            self.bad += 1
            return
        self.recv.append(Received(t, d.unit, d.seq, d.status, d.deliberating, d.planner))
        self.vec[d.unit] = d.vector if d.status in MOVING else (0.0, 0.0)

    def _on_event(self, sample: Any) -> None:
        try:
            doc = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        self.events.append((time.perf_counter(), str(sample.key_expr).rsplit("/", 1)[-1], doc))

    # output
    def put_json(self, key: str, msg: Any) -> None:
        self.session.put(key, self._encode(msg), encoding=self.enc)

    def status(self, timeout_s: float = 5.0) -> dict[str, Any] | None:
        """The responder's status reply (``msgs_in``, ``msgs_out``, ...), or ``None`` when none came.

        With several planners, their counters summed (``None`` unless every one answered).
        """
        replies = []
        for pid in self.planners:
            got = None
            for r in self.session.get(self._keys.planner_status(MISSION, pid), timeout=timeout_s):
                if r.ok is not None:
                    got = dict(json.loads(r.ok.payload.to_bytes()))
            if got is None:
                return None
            replies.append(got)
        if len(replies) == 1:
            return replies[0]
        summed = dict(replies[0])
        for k in _SUMMED:
            if all(k in r for r in replies):
                summed[k] = sum(r[k] for r in replies)
        p99 = [r["latency_p99_ms"] for r in replies if r.get("latency_p99_ms") is not None]
        summed["latency_p99_ms"] = max(p99) if p99 else None
        summed["units_owned_each"] = {r["planner"]: r.get("units_owned") for r in replies}
        summed["msgs_in_each"] = {r["planner"]: r.get("msgs_in") for r in replies}
        return summed

    def wait_ready(self, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while self.status(1.0) is None:
            if time.monotonic() > deadline:
                raise TimeoutError("the responder did not answer its status query")
            time.sleep(0.1)

    def send_state(self, unit: str, i: int | None) -> int:
        """Put one state of ``unit`` (``i``: its index, to move it first); return its seq."""
        from pfp_service.wire import UnitState

        if i is not None:
            p = self.pos[i]
            vx, vy = self.vec.get(unit, (0.0, 0.0))
            p[0] += self.step_m * vx
            p[1] += self.step_m * vy
            xy = (p[0], p[1])
        else:
            xy = (0.0, 0.0)
        seq = self.seq
        self.seq += 1
        payload = self._encode(UnitState(position=xy, seq=seq))
        t = time.perf_counter()
        self.session.put(
            self._state_keys[unit],
            payload,
            encoding=self.enc,
            congestion_control=self._zenoh.CongestionControl.BLOCK,
            express=True,
        )
        self.sent[seq] = t
        self.seq_unit[seq] = unit
        return seq

    def pace(
        self,
        rate_per_s: float,
        duration_s: float,
        units: list[int],
        tick: Callable[[float], None] | None = None,
        extra: tuple[int, float] | None = None,
        until: Callable[[], bool] | None = None,
    ) -> tuple[int, int, float]:
        """Send states of ``units`` round-robin at ``rate_per_s`` in all, for ``duration_s``.

        The round robin carries on where the last call left it.  ``extra`` =
        (unit index, Hz) adds a unit reporting at its own rate (a bystander).
        ``tick(fraction done)`` and ``until()`` are called about 5 times a
        second; ``until()`` true ends the pacing early.

        Returns:
            (first seq, one past the last seq, seconds actually spent sending).
        """
        first = self.seq
        n = len(units)
        t0 = time.perf_counter()
        end = t0 + duration_s
        k = 0
        extra_k = 0
        next_tick = t0
        while True:
            now = time.perf_counter()
            if now >= end:
                break
            due = int((now - t0) * rate_per_s) if n else 0
            while k < due:
                i = units[(self._rr + k) % n]
                self.send_state(self.ids[i], i)
                k += 1
            if extra is not None and extra_k <= (now - t0) * extra[1]:
                self.send_state(self.ids[extra[0]], extra[0])
                extra_k += 1
            if now >= next_tick:
                next_tick = now + 0.2
                if tick is not None:
                    tick(min((now - t0) / duration_s, 1.0))
                if until is not None and until():
                    break
            gaps = [(k + 1) / rate_per_s] if n else []
            if extra is not None:
                gaps.append(extra_k / extra[1])
            wait = min(gaps, default=0.002) - (time.perf_counter() - t0)
            if wait > 0:
                time.sleep(min(wait, 0.002))
        self._rr += k
        return first, self.seq, time.perf_counter() - t0

    def settle(self, quiet_s: float = 0.3, cap_s: float = 3.0) -> None:
        """Wait until no direction has arrived for ``quiet_s`` (at most ``cap_s``)."""
        deadline = time.perf_counter() + cap_s
        seen = len(self.recv)
        last = time.perf_counter()
        while time.perf_counter() < deadline:
            time.sleep(0.05)
            if len(self.recv) != seen:
                seen = len(self.recv)
                last = time.perf_counter()
            elif time.perf_counter() - last >= quiet_s:
                return
