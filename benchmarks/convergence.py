"""Plans converge: length and exposure at finer steps, down to a hundredth of the default, against the default.

The planning resolution (``step``) is the planner's business, so what the
planner chooses must not depend on it.  For the paper's scenario
(``examples/paper-simple.yaml``, at its own step of 0.1), the repository's
other example scenarios without pop-up threats, and those of ``--count``
seeded scenarios of the quality suite (``bench._cases``, escape ``auto``) that
have a way to the goal entering no threat core (``cases.reachability``, the
planner-independent raster: a shut gap has no path to converge to), this plans
at the default step and at ``FACTORS`` of it (``max_iter`` derived each time),
and reports each plan's length and exposure relative to the default's.

Target: every plan reaches, and length and exposure are within 10 % of the
default's at every finer step.  An exposure is compared relative to the
larger of the default's and ``EXPOSURE_FLOOR`` of the start-goal distance (a
path that meets almost no threat differs by noise, not by a choice).
Scenarios with a pop-up threat are left out: its ``appear_step`` is counted
in steps, so a finer step meets it earlier by construction.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

FACTORS = (0.5, 0.2, 0.1, 0.03, 0.01)
TARGET = 0.10
EXPOSURE_FLOOR = 0.001  # of the start-goal distance, in metres at peak level
EXAMPLES = ("paper-simple.yaml", "geo-simple.yaml", "zones.yaml")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--count", type=int, default=20, help="seeded scenarios of the quality suite (default: 20)"
    )
    p.add_argument("--seed", type=int, default=7, help="seed of the generated scenarios (default: 7)")
    p.add_argument("--quick", action="store_true", help="factors 0.1 and 0.01 only, 5 seeded scenarios")
    p.add_argument("--check", action="store_true", help="exit 1 when a target is missed")


def _problems(count: int, seed: int) -> list[tuple[str, dict]]:
    """(name, plan() keyword arguments) of every scenario compared."""
    from benchmarks._cases import generate, reachability
    from pfp_service.core import PlannerParams, Scheduled
    from pfp_service.core.zones import ZoneSet
    from pfp_service.scenario import load_scenario

    out: list[tuple[str, dict]] = []
    root = Path(__file__).resolve().parents[2] / "examples"
    for name in EXAMPLES:
        path = root / name
        if not path.exists():  # an installed package without the repository's examples
            continue
        sc = load_scenario(path)
        sched = sc.schedule()
        if any(s.appear_step > 0 for s in sched):
            continue
        zones = sc.zone_set()
        out.append(
            (
                name,
                dict(
                    start=sc.start,
                    goal=sc.goal,
                    schedule=sched,
                    params=sc.planner.to_params(),
                    bounds=sc.bounds,
                    zones=zones,
                ),
            )
        )
    for case in generate(count, seed):
        if reachability(case).reachable is not True:
            continue  # no way that enters no core (or not clearly one): nothing to converge to
        out.append(
            (
                case.name,
                dict(
                    start=case.start,
                    goal=case.goal,
                    schedule=[Scheduled(t) for t in case.threats],
                    params=PlannerParams(escape="auto"),
                    bounds=case.bounds,
                    zones=ZoneSet(case.zones) if case.zones else None,
                ),
            )
        )
    return out


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from pfp_service.core import plan, resolve

    factors = (0.1, 0.01) if args.quick else FACTORS
    count = 5 if args.quick else args.count
    print(
        f"# pfp bench convergence (load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}): length and exposure at step x{list(factors)}"
    )
    misses: list[str] = []
    worst = 0.0
    t0 = time.perf_counter()
    for name, kw in _problems(count, args.seed):
        params = kw.pop("params")
        threats = [s.threat for s in kw["schedule"]]
        base = resolve(params, kw["start"], kw["goal"], threats)
        d0 = math.dist(kw["start"], kw["goal"])
        ref = plan(params=dataclasses.replace(params, step=base.step, max_iter=None), **kw)
        cells = [f"{name:24} step {base.step:9.4g}  L {ref.length:10.2f}  E {ref.exposure:9.4g}"]
        if ref.status.value != "reached":
            misses.append(f"{name}: the default step's plan is {ref.status.value}")
        floor = max(ref.exposure, EXPOSURE_FLOOR * d0)
        for f in factors:
            r = plan(params=dataclasses.replace(params, step=base.step * f, max_iter=None), **kw)
            dl = abs(r.length - ref.length) / ref.length if ref.length > 0 else 0.0
            de = abs(r.exposure - ref.exposure) / floor if floor > 0 else 0.0
            worst = max(worst, dl, de)
            cells.append(f"x{f:g}: {100 * dl:4.1f}%/{100 * de:4.1f}%")
            if r.status.value != "reached":
                misses.append(f"{name} at x{f:g}: {r.status.value} ({r.reason})")
            elif dl > TARGET or de > TARGET:
                misses.append(
                    f"{name} at x{f:g}: length {100 * dl:.1f} %, exposure {100 * de:.1f} % off the default"
                )
        print("  ".join(cells))
    print(f"worst difference {100 * worst:.1f} % ({time.perf_counter() - t0:.0f} s)")
    for m in misses:
        print(f"MISSED: {m}")
    if not misses:
        print("every target met")
    return 1 if args.check and misses else 0
