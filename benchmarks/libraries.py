"""Kept libraries against our own code: pebble's pool and pynmea2's parser, on what the planner needs of them.

Two questions, each measured in one run against our code:

* **The worker pool** (``node/workers.py``).  A preview or look-ahead past its
  deadline is killed with its worker, and the next task must not wait for a
  cold replacement.  pebble's ``ProcessPool`` also kills one timed-out task,
  but its workers come from ``multiprocessing`` contexts: ``fork`` is unsafe
  in a process holding a Zenoh session, and ``forkserver``/``spawn`` start a
  fresh interpreter that must load the numba kernels again (``initializer``).
  Ours forks a warm fork server and keeps a warm spare.  The figure: from a task
  killed at its deadline to the next task's answer, each pool with one worker.
* **The NMEA parser** (``clients/pfp_clients/nmea.py``).  A handheld fed a
  hostile or broken receiver must never be placed at a wrong fix.  The
  figures: which of a set of malformed GGA sentences each parser turns into
  a fix, and the time per good sentence.

Both libraries are dev-only dependencies, for this measurement.  The verdict
is in docs/development.md ("Libraries weighed").
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import statistics
import threading
import time
from typing import Any

from pfp_service.argtypes import positive_int

__all__ = ["add_arguments", "run"]

_GOOD_BODY = "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
# each a GGA sentence no honest receiver sends: a parser must refuse it (or say "no fix"), never fix it
_HOSTILE = {
    "minutes past 59": "GPGGA,123519,4861.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    "latitude 95 degrees": "GPGGA,123519,9507.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    "hemisphere X": "GPGGA,123519,4807.038,X,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    "NaN latitude": "GPGGA,123519,nan,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    "inf longitude": "GPGGA,123519,4807.038,N,inf,E,1,08,0.9,545.4,M,46.9,M,,",
    "quality 0 (no fix)": "GPGGA,123519,4807.038,N,01131.000,E,0,08,0.9,545.4,M,46.9,M,,",
    "empty latitude": "GPGGA,123519,,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    "5,000-character line": "GPGGA," + "1" * 5000,
    "time 25:00": "GPGGA,250000,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rounds", type=positive_int, default=5, help="killed tasks per pool (default 5)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


# -- the pool -----------------------------------------------------------------------------
def _plan_args() -> tuple[Any, ...]:
    from pfp_service.core.plan import Scheduled
    from pfp_service.core.threat import Threat

    threat = Threat.from_facing((5.0, 5.0), 0.0, 1.0, 0.7, 0.0, 1.0, "t")
    return (0.0, 0.0), (10.0, 10.0), [Scheduled(threat)]


def _ours(rounds: int) -> list[float]:
    """Seconds from a task killed at its 0.2 s budget to the next task's answer, in our pool as ``pfp serve`` runs it."""
    import gc

    from pfp_service.core.plan import plan
    from pfp_service.node.forkserver import ForkServer, install_fork_server
    from pfp_service.node.previews import warm_up
    from pfp_service.node.tasks import Outcome, Task
    from pfp_service.node.workers import KILL_GRACE_S, WorkerPool

    warm_up(None)  # as pfp serve starts: warm, frozen, the fork server forked before any thread
    gc.freeze()
    install_fork_server(ForkServer.start())
    pool = WorkerPool("bench", 1, warm="pfp_service.node.previews:_warm_worker", spare=True)
    try:
        pool.wait_ready(120)
        out = []
        for _ in range(rounds):
            done = threading.Event()
            got: list[Outcome] = []
            pool.submit(Task(time.sleep, (60.0,), lambda o: None, budget_s=0.2))
            t0 = time.monotonic()

            def answered(o: Outcome) -> None:
                got.append(o)
                done.set()

            pool.submit(Task(plan, _plan_args(), answered, budget_s=30.0))
            done.wait(120)
            if not got or got[0].kind != "done":
                raise RuntimeError(f"our pool answered {got[0].kind if got else 'nothing'}")
            out.append(time.monotonic() - t0 - 0.2 - KILL_GRACE_S)  # the hard stop is budget + grace
            time.sleep(1.0)  # the spare comes back
        return out
    finally:
        pool.shutdown()
        install_fork_server(None)


def _pebble(rounds: int) -> list[float] | str:
    """The same with pebble's ``ProcessPool`` (forkserver context, the kernels warmed in its initializer)."""
    try:
        from pebble import ProcessPool
    except ImportError:
        return "pebble is not installed (pip install pebble)"
    from pfp_service.core.plan import plan
    from pfp_service.node.previews import _warm_worker

    pool = ProcessPool(max_workers=1, context=mp.get_context("forkserver"), initializer=_warm_worker)
    try:
        pool.schedule(plan, args=_plan_args()).result(120)
        out = []
        for _ in range(rounds):
            pool.schedule(time.sleep, args=(60.0,), timeout=0.2)
            t0 = time.monotonic()
            pool.schedule(plan, args=_plan_args(), timeout=30.0).result(120)
            out.append(time.monotonic() - t0 - 0.2)
            time.sleep(1.0)
        return out
    finally:
        pool.stop()
        pool.join()


# -- the NMEA parser ----------------------------------------------------------------------
def _nmea() -> dict[str, Any]:
    from pfp_clients.nmea import nmea_checksum, parse_gga

    from pfp_service.errors import InputError

    def line(body: str) -> str:
        return f"${body}*{nmea_checksum(body):02X}"

    def ours(s: str) -> str:
        try:
            fix = parse_gga(s)
        except InputError:
            return "refused"
        return "no fix" if fix is None else f"fix {fix.lat_deg:.4f},{fix.lon_deg:.4f}"

    try:
        import pynmea2
    except ImportError:
        return {"error": "pynmea2 is not installed (pip install pynmea2)"}

    def theirs(s: str) -> str:
        try:
            m = pynmea2.parse(s, check=True)
            lat, lon = m.latitude, m.longitude
        except Exception:  # whatever it raises is a refusal here
            return "refused"
        return "no fix" if str(m.gps_qual) == "0" else f"fix {lat:.4f},{lon:.4f}"

    cases = {name: {"ours": ours(line(b)), "pynmea2": theirs(line(b))} for name, b in _HOSTILE.items()}
    good, n, per = line(_GOOD_BODY), 20_000, {}
    for name, fn in (("ours", parse_gga), ("pynmea2", lambda s: pynmea2.parse(s, check=True).latitude)):
        t0 = time.perf_counter()
        for _ in range(n):
            fn(good)
        per[f"{name}_us"] = (time.perf_counter() - t0) / n * 1e6
    return {
        "cases": cases,
        "fixed_from_hostile": {
            k: sum(c[k].startswith("fix") for c in cases.values()) for k in ("ours", "pynmea2")
        },
        **per,
    }


def run(args: argparse.Namespace) -> int:
    load = os.getloadavg()
    nmea = _nmea()  # first: the pool's fork server must fork before any thread
    ours = _ours(args.rounds)
    pebble = _pebble(args.rounds)
    doc: dict[str, Any] = {
        "load_before": load,
        "pool_ours_ms": [round(x * 1e3) for x in ours],
        "pool_pebble_ms": pebble if isinstance(pebble, str) else [round(x * 1e3) for x in pebble],
        "nmea": nmea,
        "load_after": os.getloadavg(),
    }
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"pfp bench libraries (load average before {load[0]:.2f}, after {doc['load_after'][0]:.2f})\n")
    print("worker pool: from a task killed at its deadline to the next task's answer (one worker)")
    print(
        f"  ours (warm fork server, warm spare): median {statistics.median(ours) * 1e3:.0f} ms, max {max(ours) * 1e3:.0f} ms"
    )
    if isinstance(pebble, str):
        print(f"  pebble: {pebble}")
    else:
        print(
            f"  pebble ProcessPool (forkserver):  median {statistics.median(pebble) * 1e3:.0f} ms, "
            f"max {max(pebble) * 1e3:.0f} ms"
        )
    print("\nNMEA GGA: hostile sentences turned into a fix (a wrong place for a soldier)")
    if "error" in nmea:
        print(f"  {nmea['error']}")
        return 0
    for name, c in nmea["cases"].items():
        print(f"  {name:22} ours: {c['ours']:24} pynmea2: {c['pynmea2']}")
    f = nmea["fixed_from_hostile"]
    print(f"  fixes from {len(_HOSTILE)} hostile sentences: ours {f['ours']}, pynmea2 {f['pynmea2']}")
    print(f"  a good sentence: ours {nmea['ours_us']:.1f} us, pynmea2 {nmea['pynmea2_us']:.1f} us")
    return 0
