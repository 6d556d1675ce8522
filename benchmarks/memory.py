"""Memory: an idle planner's process tree, then the same tree with many units reporting (PSS, summed).

``pfp serve --state-dir none`` runs in its own process (router mode, a free
loopback port); this process is the load generator.  Phases:

1. **idle**: ``--idle-s`` seconds after the planner started, the proportional
   set size (PSS, ``/proc/*/smaps_rollup``) of the planner and of every
   process under it (its fork server and workers), summed, and each one's;
2. **loaded**: ``--threats`` threats are put, ``--units`` units report and
   get goals, then report at ``--rate`` Hz for ``--load-s`` seconds; the tree's
   PSS is sampled every second, and its peak and last value reported;
3. **quiet**: ``QUIET_S`` seconds after the load stopped, once more: what the
   planner gives back when its backlog is gone.

Each figure also splits the planner's own PSS by mapping (``/proc/PID/smaps``):
``heap`` (glibc's main arena, ``[heap]``), ``anon`` (anonymous mappings: the
other malloc arena, large ``mmap`` allocations, CPython's object arenas and
Zenoh's buffers), ``file`` (libraries and compiled kernels) and ``other``
(stacks, vdso), to say where growth goes.

PSS counts a page shared by k processes as 1/k in each, so the sum over the
tree is what the tree costs the machine.  A library's file pages are shared
with every other process mapping it too (other Python programs on the
machine lower the figure a little): compare figures of one run, or runs on
the same machine.
"""

from __future__ import annotations

import argparse
import json
import re
import threading
import time
from typing import Any

from benchmarks._check import add_check_arg, exit_code
from benchmarks._layout import layout
from benchmarks._load import MISSION, LoadGen, start_server
from benchmarks._phases import STEP_M, Bar, register, steady
from benchmarks._procs import tree_pss_by_process
from pfp_service.argtypes import positive_float, positive_int

__all__ = ["TARGETS", "add_arguments", "run", "targets"]

TARGETS = {"idle_pss_mb": 250.0, "loaded_pss_mb": 400.0}  # issue 23, at 10,000 units and 1 Hz
SAMPLE_S = 1.0
QUIET_S = 5.0  # after the load stops, this long before the quiet figure
_MAPPING = re.compile(r"^[0-9a-f]+-[0-9a-f]+ ")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--units", type=positive_int, default=10_000, help="units (default 10000)")
    p.add_argument("--rate", type=positive_float, default=1.0, help="reports per unit per second (default 1)")
    p.add_argument("--threats", type=int, default=100, help="threats in the field (default 100)")
    p.add_argument(
        "--idle-s",
        type=positive_float,
        default=40.0,
        help="idle seconds before the first figure (default 40)",
    )
    p.add_argument("--load-s", type=positive_float, default=30.0, help="seconds of load (default 30)")
    p.add_argument("--seed", type=int, default=1, help="layout seed (default 1)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    add_check_arg(p)


def _loadavg() -> float:
    with open("/proc/loadavg") as f:
        return float(f.read().split()[0])


def pss_by_mapping(smaps: str) -> dict[str, float]:
    """PSS in MB of one process by kind of mapping, from the text of its ``/proc/PID/smaps``.

    ``heap`` is ``[heap]``; ``anon`` a mapping with no name; ``file`` one named by
    a path; ``other`` the rest (``[stack]``, ``[vdso]`` ...).
    """
    kb = {"heap": 0, "anon": 0, "file": 0, "other": 0}
    kind = "other"
    for line in smaps.splitlines():
        if _MAPPING.match(line):
            parts = line.split(maxsplit=5)
            name = parts[5].strip() if len(parts) > 5 else ""
            if name == "[heap]":
                kind = "heap"
            elif not name:
                kind = "anon"
            elif name.startswith("/"):
                kind = "file"
            else:
                kind = "other"
        elif line.startswith("Pss:"):
            kb[kind] += int(line.split()[1])
    return {k: round(v / 1024, 1) for k, v in kb.items()}


def _by_mapping(pid: int) -> dict[str, float] | None:
    try:
        with open(f"/proc/{pid}/smaps") as f:
            return pss_by_mapping(f.read())
    except OSError:
        return None


def _snapshot(pid: int) -> dict[str, Any]:
    each = tree_pss_by_process(pid)
    return {
        "pss_mb": round(sum(each.values()), 1),
        "processes": len(each),
        "pss_mb_by_process": [round(v, 1) for v in each.values()],  # the planner first, then its tree
        "planner_by_mapping": _by_mapping(pid),
        "loadavg": _loadavg(),
    }


class _Sampler:
    """The tree's PSS every ``SAMPLE_S`` on a thread; ``peak`` is the largest sum seen."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.peak: dict[str, Any] | None = None
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, name="pss-sampler", daemon=True)
        self._t.start()

    def _run(self) -> None:
        while not self._stop.wait(SAMPLE_S):
            snap = _snapshot(self.pid)
            if self.peak is None or snap["pss_mb"] > self.peak["pss_mb"]:
                self.peak = snap

    def stop(self) -> dict[str, Any] | None:
        self._stop.set()
        self._t.join()
        return self.peak


def measure(args: argparse.Namespace, bar: Bar) -> dict[str, Any]:
    from pfp_service.wire import Goal, keys

    lay = layout(args.units, args.threats, args.seed)
    srv = start_server("planner")
    started = time.monotonic()
    g: LoadGen | None = None
    res: dict[str, Any] = {"units": args.units, "rate_hz": args.rate, "threats": args.threats}
    try:
        g = LoadGen(srv.endpoint, lay["starts"], STEP_M)
        g.wait_ready()
        time.sleep(max(0.0, args.idle_s - (time.monotonic() - started)))
        res["idle"] = _snapshot(srv.proc.pid) | {"after_s": round(time.monotonic() - started, 1)}
        for tid, t in lay["threats"]:
            g.put_json(keys.threat(MISSION, tid), t)
        res["registered"] = register(g, args.units)
        for i in range(args.units + 1):
            g.put_json(keys.unit_goal(MISSION, g.ids[i]), Goal(position=lay["goals"][i], step=STEP_M))
        g.settle(0.5, 10.0)
        sampler = _Sampler(srv.proc.pid)
        try:
            st = steady(g, srv, args.units, args.rate, args.load_s, bar, "load")
        finally:
            peak = sampler.stop()
        res["loaded"] = {
            "peak": peak,
            "last": _snapshot(srv.proc.pid),
            "answered_per_s": st.get("answered_per_s"),
            "unanswered": st.get("unanswered_fraction"),
            "p99_ms": st.get("p99_ms"),
        }
        time.sleep(QUIET_S)  # the load has stopped: what the planner keeps once its backlog is gone
        res["quiet"] = _snapshot(srv.proc.pid)
    finally:
        if g is not None:
            g.close()
        res["exit"] = srv.stop()
    return res


def targets(doc: dict[str, Any]) -> list[dict[str, Any]]:
    peak = (doc.get("loaded") or {}).get("peak") or {}
    rows = [
        ("idle PSS of the tree <= 250 MB", doc.get("idle", {}).get("pss_mb"), TARGETS["idle_pss_mb"]),
        (
            f"PSS with {doc['units']} units at {doc['rate_hz']:g} Hz <= 400 MB",
            peak.get("pss_mb"),
            TARGETS["loaded_pss_mb"],
        ),
    ]
    return [
        {"target": name, "measured": m, "limit": lim, "met": None if m is None else m <= lim}
        for name, m, lim in rows
    ]


def run(args: argparse.Namespace) -> int:
    with Bar() as bar:
        doc = measure(args, bar)
    doc["targets"] = targets(doc)
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        idle = doc.get("idle", {})
        print(
            f"idle: {idle.get('pss_mb')} MB PSS in {idle.get('processes')} processes "
            f"{idle.get('pss_mb_by_process')} after {idle.get('after_s')} s, load avg {idle.get('loadavg')}"
        )
        loaded = doc.get("loaded", {})
        for which, s in (
            ("loaded peak", loaded.get("peak") or {}),
            ("loaded last", loaded.get("last") or {}),
            (f"quiet {QUIET_S:g} s after", doc.get("quiet") or {}),
        ):
            print(
                f"{which}: {s.get('pss_mb')} MB PSS in {s.get('processes')} processes "
                f"{s.get('pss_mb_by_process')} (planner by mapping {s.get('planner_by_mapping')}), "
                f"load avg {s.get('loadavg')}"
            )
        print(
            f"load: {doc['units']} units x {doc['rate_hz']:g} Hz, answered {loaded.get('answered_per_s')}/s, "
            f"unanswered {loaded.get('unanswered')}, p99 {loaded.get('p99_ms')} ms; exit {doc['exit']}"
        )
        for t in doc["targets"]:
            verdict = "n/a" if t["met"] is None else ("[ok]" if t["met"] else "[MISSED]")
            print(f"  {t['target']}: {t['measured']} -> {verdict}")
    return exit_code((t["met"] for t in doc["targets"]), args.check)
