"""Path quality per escape mode on a seeded trap suite, against the core-avoiding optimum.

For every generated scenario (``bench._cases``) and every escape mode this
plans once, then reports: the reach rate over the *reachable* scenarios, the
honest-``trapped`` rate on the *enclosed* ones (no ``reached`` there is
honest), paths entering a threat core, median and worst length and exposure
(as multiples of the scenario's start-goal distance, since sizes span
10-30,000 m), and compute time.  Reachable, enclosed or *ambiguous* is decided
independently of every planner (``cases.reachability``: a raster of the cores
and a connected-component count, across the core band 0.48-0.52); ambiguous
cases count in no rate.

Path cost: each reached path's ``J = length + LAMBDA exposure`` relative to
``J*``, the optimal planner's with ``avoid_cores`` at ``LAMBDA`` (``J / J*``;
a little below 1 where the grid reference is itself off the optimum, or where
a narrow open gap is finer than its grid).

Pareto gap: the optimal planner is solved for ``lambda`` in ``LAMBDAS``.  Of
the optimal paths that are no longer *and* no more exposed than a PFP path,
take the one that beats it most on both, i.e. maximise
``min(1 - L_opt / L_pfp, 1 - E_opt / E_pfp)``; that minimum is the gap (0 when
none beats it on both); the sweep ignores cores, so it is a lower bound.
``--write`` puts the tables in BENCHMARKS.md between markers, so the file can
hold other benchmarks too.

``--family zones`` runs the keep-out zone family instead (``bench._zone_cases``):
the same table, with every plan among the case's zones, ``J*`` from the
zone-aware optimum (``--planner optimal --avoid-cores`` with the zones), the
entries column counting paths that touch a zone or a core (zones checked
exactly, segment by segment) and reachability from shapely and a raster
(``zone_cases.zone_reachability``).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import msgspec
import numpy as np

from benchmarks._cases import KINDS
from benchmarks._check import add_check_arg, exit_code
from pfp_service.argtypes import grid_cells
from pfp_service.core.options import ESCAPES, LAMBDA

if TYPE_CHECKING:
    from benchmarks._cases import Case

__all__ = ["LAMBDAS", "add_arguments", "run"]

LAMBDAS = (0.0, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)
FAMILIES = ("traps", "zones")
BEGIN, END = "<!-- pfp bench quality: begin -->", "<!-- pfp bench quality: end -->"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--scenarios", type=int, default=4 * len(KINDS), help=f"how many scenarios (default {4 * len(KINDS)})"
    )
    p.add_argument("--seed", type=int, default=2023, help="suite seed (default 2023)")
    p.add_argument(
        "--family",
        choices=FAMILIES,
        default="traps",
        help="the threat trap suite (default) or the keep-out zone family (zones)",
    )
    p.add_argument("--modes", default=",".join(ESCAPES), help="comma-separated escape modes")
    p.add_argument(
        "--cells", type=grid_cells, default=200, help="optimal-planner grid cells on the longer side"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_check_arg(p)
    p.add_argument(
        "--write", metavar="MD", nargs="?", const="BENCHMARKS.md", help="update this markdown file"
    )


@dataclass
class Row:
    case: str
    kind: str
    mode: str
    status: str
    traps: int
    escapes: list[str]
    escape_steps: int
    length_rel: float  # length / start-goal distance
    exposure_rel: float  # exposure / start-goal distance
    compute_ms: float  # wall clock, median of the runs
    core_entry: str
    cpu_ms: float = math.nan  # process CPU time, median of the runs
    gap: float | None = None
    gap_shorter: float | None = None
    gap_less_exposed: float | None = None
    j_ratio: float | None = None  # (L + LAMBDA E) / J* against the core-avoiding optimum


@dataclass
class Report:
    seed: int
    scenarios: int
    reachable: list[str]
    enclosed: list[str]
    disagreements: list[str]
    ambiguous: list[str] = field(default_factory=list)
    rows: list[Row] = field(default_factory=list)
    targets: dict[str, object] = field(default_factory=dict)
    family: str = "traps"


def _pareto(length: float, exposure: float, opts: list[tuple[float, float]]) -> tuple[float, float, float]:
    best = (0.0, 0.0, 0.0)
    for lo, eo in opts:
        if lo <= length and eo <= exposure:
            dl = 1.0 - lo / length if length > 0 else 0.0
            de = 1.0 - eo / exposure if exposure > 0 else 0.0
            if min(dl, de) > best[0]:
                best = (min(dl, de), dl, de)
    return best


def _timed_plan(case: Case, mode: str, repeat: int) -> tuple[object, float, float]:
    """The plan, and the medians over ``repeat`` runs of its wall-clock and process CPU milliseconds."""
    from pfp_service.core import PlannerParams, Scheduled, plan
    from pfp_service.core.zones import ZoneSet

    sched = [Scheduled(t) for t in case.threats]
    zones = ZoneSet(case.zones) if case.zones else None
    times, cpu, result = [], [], None
    for _ in range(repeat):
        c0 = time.process_time()
        result = plan(
            case.start,
            case.goal,
            sched,
            PlannerParams(escape=mode),  # type: ignore[arg-type]
            case.bounds,
            time.perf_counter,
            zones=zones,
        )
        cpu.append(1e3 * (time.process_time() - c0))
        times.append(result.compute_ms)
    return result, statistics.median(times), statistics.median(cpu)


def measure_suite(
    count: int, seed: int, modes: list[str], cells: int, log: bool = False, family: str = "traps"
) -> Report:
    """Run the whole benchmark and return its figures (no printing unless ``log``)."""
    # the compiled core here, not at the top: `pfp` imports this module to build its parser
    from benchmarks._cases import generate, reachability
    from benchmarks._zone_cases import generate_zones, zone_reachability
    from pfp_service.core import PlannerParams, Scheduled, ThreatField, plan
    from pfp_service.core.cores import Cores
    from pfp_service.core.optimal import OptimalSolver
    from pfp_service.core.zones import ZoneSet

    cases = generate_zones(count, seed) if family == "zones" else generate(count, seed)
    rep = Report(seed, count, [], [], [], family=family)
    plan(
        cases[0].start,
        cases[0].goal,
        [Scheduled(t) for t in cases[0].threats],
        PlannerParams(escape="auto"),
        zones=ZoneSet(cases[0].zones) if cases[0].zones else None,
    )  # warm-up: compile the kernels outside the timings
    for case in cases:
        fieldm = ThreatField(case.threats, zones=ZoneSet(case.zones) if case.zones else None)
        d0 = math.hypot(case.goal[0] - case.start[0], case.goal[1] - case.start[1])
        truth = (zone_reachability(case) if family == "zones" else reachability(case)).reachable
        {True: rep.reachable, False: rep.enclosed, None: rep.ambiguous}[truth].append(case.name)
        if truth is not None and truth == case.enclosed:
            rep.disagreements.append(case.name)
        solver = OptimalSolver(fieldm, case.start, case.goal, case.bounds, cells)
        opts = [(o.length, o.exposure) for o in (solver.solve(lam) for lam in LAMBDAS)]
        j_star = math.nan
        if truth:
            ref = OptimalSolver(fieldm, case.start, case.goal, case.bounds, cells, avoid_cores=True)
            j_star = ref.solve(LAMBDA).cost
        cores = Cores(fieldm)
        for mode in modes:
            r, ms, cpu_ms = _timed_plan(case, mode, 3 if mode in ("none", "auto") else 1)
            row = Row(
                case.name,
                case.kind,
                mode,
                r.status.value,  # type: ignore[attr-defined]
                r.traps,  # type: ignore[attr-defined]
                r.escapes,  # type: ignore[attr-defined]
                r.escape_steps,  # type: ignore[attr-defined]
                r.length / d0,  # type: ignore[attr-defined]
                r.exposure / d0,  # type: ignore[attr-defined]
                ms,
                cores.first_hit(np.asarray(r.path)),  # type: ignore[attr-defined]
                cpu_ms=cpu_ms,
            )
            if row.status == "reached":
                row.gap, row.gap_shorter, row.gap_less_exposed = _pareto(
                    r.length,  # type: ignore[attr-defined]
                    r.exposure,  # type: ignore[attr-defined]
                    opts,
                )
                if math.isfinite(j_star):
                    row.j_ratio = (r.length + LAMBDA * r.exposure) / j_star  # type: ignore[attr-defined]
            rep.rows.append(row)
            if log:
                print(
                    f"{case.name:22s} {mode:8s} {row.status:8s} traps={row.traps} {row.escapes} "
                    f"L={row.length_rel:.3f} E={row.exposure_rel:.4f} gap={row.gap} {ms:.1f} ms {row.core_entry}",
                    file=sys.stderr,
                )
    rep.targets = _targets(rep)
    return rep


def _med(xs: list[float]) -> float:
    return statistics.median(xs) if xs else math.nan


def _quantile(xs: list[float], q: float) -> float:
    return float(np.quantile(xs, q)) if xs else math.nan


TARGETS = {
    "reach": ("auto reaches 100 % of the reachable cases", 1.0),
    "false_reached": ("0 false reached (enclosed cases)", 0),
    "honest": ("honestly traps 100 % of the enclosed cases", 1.0),
    "j_median": ("J / J* median <= 1.02", 1.02),
    "j_p90": ("J / J* 90th percentile <= 1.10", 1.10),
    "j_worst": ("J / J* worst <= 1.5", 1.5),
    "ms_median": ("plan compute median <= 20 ms (wall clock)", 20.0),
    "ms_worst": ("plan compute worst <= 500 ms (wall clock)", 500.0),
    "cpu_median": ("plan compute median <= 20 ms (process CPU time)", 20.0),
    "cpu_worst": ("plan compute worst <= 500 ms (process CPU time)", 500.0),
}


def _targets(rep: Report) -> dict[str, object]:
    auto = [r for r in rep.rows if r.mode == "auto"]
    reach = [r for r in auto if r.case in rep.reachable]
    encl = [r for r in auto if r.case in rep.enclosed]
    js = [r.j_ratio for r in reach if r.j_ratio is not None]
    ms = [r.compute_ms for r in auto]
    cpu = [r.cpu_ms for r in auto]
    measured: dict[str, float] = {
        "reach": sum(r.status == "reached" for r in reach) / len(reach) if reach else math.nan,
        "false_reached": sum(r.status == "reached" for r in encl),
        "honest": sum(r.status == "trapped" for r in encl) / len(encl) if encl else math.nan,
        "j_median": _med(js),
        "j_p90": _quantile(js, 0.9),
        "j_worst": max(js, default=math.nan),
        "ms_median": _med(ms),
        "ms_worst": max(ms, default=math.nan),
        "cpu_median": _med(cpu),
        "cpu_worst": max(cpu, default=math.nan),
    }
    met = {}
    for key, (_label, goal) in TARGETS.items():
        v = measured[key]
        met[key] = v >= goal if key in ("reach", "honest") else v <= goal
    return {"measured": measured, "met": met}


def _fmt(x: float | None, pct: bool = False) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{100 * x:.1f} %" if pct else f"{x:.3g}"


def render(rep: Report, modes: list[str]) -> str:
    """The markdown tables."""
    lines = [
        f"Suite: {rep.scenarios} scenarios, seed {rep.seed}; {len(rep.reachable)} reachable, "
        f"{len(rep.enclosed)} enclosed (no way avoids every threat core{' and zone' if rep.family == 'zones' else ''}), "
        f"{len(rep.ambiguous)} ambiguous"
        + (f" ({', '.join(rep.ambiguous)})" if rep.ambiguous else "")
        + (
            ", by shapely and a raster of the zones and cores, independent of the planners."
            if rep.family == "zones"
            else ", by a core raster independent of the planners."
        )
        + (
            f" Generator intent and ground truth differ on: {', '.join(rep.disagreements)}."
            if rep.disagreements
            else ""
        ),
        "",
        f"| escape | reached (reachable) | honest trapped (enclosed) | paths entering a {'zone or ' if rep.family == 'zones' else ''}core | median / worst length "
        "(x D0) | median / worst exposure (x D0) | median / worst Pareto gap | median / max compute ms | "
        "median / max CPU ms |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for mode in modes:
        rows = [r for r in rep.rows if r.mode == mode]
        reach = [r for r in rows if r.case in rep.reachable]
        encl = [r for r in rows if r.case in rep.enclosed]
        ok = [r for r in rows if r.status == "reached"]
        gaps = [r.gap for r in ok if r.gap is not None]
        honest = sum(r.status == "trapped" for r in encl)
        lines.append(
            f"| {mode} | {sum(r.status == 'reached' for r in reach)}/{len(reach)} | {honest}/{len(encl)} | "
            f"{sum(bool(r.core_entry) for r in rows)} | "
            f"{_fmt(_med([r.length_rel for r in ok]))} / {_fmt(max((r.length_rel for r in ok), default=None))} | "
            f"{_fmt(_med([r.exposure_rel for r in ok]))} / {_fmt(max((r.exposure_rel for r in ok), default=None))} | "
            f"{_fmt(_med(gaps), True)} / {_fmt(max(gaps, default=None), True)} | "
            f"{_fmt(_med([r.compute_ms for r in rows]))} / {_fmt(max(r.compute_ms for r in rows))} | "
            f"{_fmt(_med([r.cpu_ms for r in rows]))} / {_fmt(max(r.cpu_ms for r in rows))} |"
        )
    t = rep.targets
    measured, met = t["measured"], t["met"]
    assert isinstance(measured, dict) and isinstance(met, dict)
    lines += ["", "| target (auto) | measured | met |", "|---|---|---|"]
    for key, (label, _goal) in TARGETS.items():
        v = measured[key]
        shown = (
            _fmt(v, True) if key in ("reach", "honest") else (str(v) if key == "false_reached" else _fmt(v))
        )
        lines.append(f"| {label} | {shown} | {'yes' if met[key] else 'no'} |")
    by_kind: dict[str, list[Row]] = {}
    for r in rep.rows:
        if r.mode == "auto":
            by_kind.setdefault(r.kind, []).append(r)
    lines += [
        "",
        "`auto` by kind:",
        "",
        "| kind | scenarios | reached | trapped | escapes used | median gap | median / worst J / J* | median / worst ms | median / worst CPU ms |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for kind, rows in by_kind.items():
        used = sorted({e for r in rows for e in r.escapes})
        gaps = [r.gap for r in rows if r.gap is not None]
        js = [r.j_ratio for r in rows if r.j_ratio is not None]
        lines.append(
            f"| {kind} | {len(rows)} | {sum(r.status == 'reached' for r in rows)} | "
            f"{sum(r.status == 'trapped' for r in rows)} | {', '.join(used) or '-'} | {_fmt(_med(gaps), True)} | "
            f"{_fmt(_med(js))} / {_fmt(max(js, default=None))} | "
            f"{_fmt(_med([r.compute_ms for r in rows]))} / {_fmt(max(r.compute_ms for r in rows))} | "
            f"{_fmt(_med([r.cpu_ms for r in rows]))} / {_fmt(max(r.cpu_ms for r in rows))} |"
        )
    lines += [
        "",
        "A Pareto gap of 0 means that no path of the optimal planner's lambda sweep (cores ignored) is both "
        f"shorter and less exposed. J / J* compares `length + {LAMBDA:g} exposure` with the core-avoiding "
        "optimum's (`--planner optimal --avoid-cores`; below 1 where the grid reference is itself slightly "
        "off the optimum). Compute is wall clock (`compute_ms`) and the planning process's CPU time, each the "
        "median of 3 runs for none and auto: the 2-core machine is shared, and wall clock under contention "
        "runs 3-6x the CPU time.",
    ]
    return "\n".join(lines)


def _write(path: str, body: str, machine: str, family: str = "traps") -> None:
    p = Path(path)
    text = p.read_text() if p.exists() else "# Benchmarks\n"
    begin, end, title, flag = BEGIN, END, "Path quality", ""
    if family != "traps":  # its own block: the trap suite's stays
        begin, end = (
            BEGIN.replace("quality:", f"quality {family}:"),
            END.replace("quality:", f"quality {family}:"),
        )
        title, flag = f"Path quality, the {family} family", f" --family {family}"
    block = (
        f"{begin}\n## {title} (`pfp bench quality{flag}`)\n\nRegenerate with `pfp bench quality{flag} --write`. "
        f"Machine: {machine}.\n\n{body}\n{end}"
    )
    BEGIN_, END_ = begin, end
    if BEGIN_ in text and END_ in text:
        text = text[: text.index(BEGIN_)] + block + text[text.index(END_) + len(END_) :]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    p.write_text(text)


def run(args: argparse.Namespace) -> int:
    modes = [m for m in args.modes.split(",") if m]
    bad = [m for m in modes if m not in ESCAPES]
    if bad or args.scenarios < 1:
        print(
            f"pfp bench quality: --modes: unknown {bad}"
            if bad
            else "pfp bench quality: --scenarios: must be >= 1",
            file=sys.stderr,
        )
        return 2
    if "none" not in modes:
        modes.insert(0, "none")
    if "auto" not in modes:
        modes.insert(1, "auto")
    import os

    load0 = os.getloadavg()[0]
    rep = measure_suite(args.scenarios, args.seed, modes, args.cells, log=not args.json, family=args.family)
    load1 = os.getloadavg()[0]
    body = render(rep, modes)
    if args.json:
        sys.stdout.write(msgspec.json.encode(rep).decode() + "\n")
    else:
        print(body)
    if args.write:
        import platform

        _write(
            args.write,
            body,
            f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
            f"; 1-minute load average {load0:.1f} at the start and {load1:.1f} at the end (the machine is shared)",
            args.family,
        )
    met = rep.targets.get("met", {})
    return exit_code(met.values() if isinstance(met, dict) else [], args.check)
