"""``pfp plan``: plan one scenario file and report the path and its quality."""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from typing import Any

from pfp_service.cli._common import positive_float, positive_int
from pfp_service.core.params import ESCAPES


def register(sub: Any) -> None:
    p = sub.add_parser("plan", help="plan a scenario file (YAML or JSON)", description=__doc__)
    p.add_argument("scenario", help="scenario file (.yaml, .yml or .json)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a summary")
    p.add_argument("--plot", metavar="PNG", help="write threat contours, start, goal and path to PNG")
    p.add_argument("--repeat", type=positive_int, default=1, metavar="N", help="compute_ms is the median of N runs")
    p.add_argument("--delta", type=positive_float, help="override the goal weight delta")
    p.add_argument("--step", type=positive_float, help="override the step length (m)")
    p.add_argument("--tolerance", type=positive_float, help="override the arrival tolerance (m)")
    p.add_argument("--max-iter", type=positive_int, help="override the iteration limit")
    p.add_argument("--intensity", choices=("peak", "density"), help="override the intensity scale")
    p.add_argument("--escape", choices=ESCAPES, help="override the trap-escape strategy")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import msgspec

    from pfp_service.core import plan
    from pfp_service.report import summary
    from pfp_service.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    params = scenario.planner.to_params().merged(
        delta=args.delta,
        step=args.step,
        tolerance=args.tolerance,
        max_iter=args.max_iter,
        intensity=args.intensity,
        escape=args.escape,
    )
    schedule = scenario.schedule()
    times = []
    for _ in range(args.repeat):
        result = plan(scenario.start, scenario.goal, schedule, params, scenario.bounds_tuple(), time.perf_counter)
        times.append(result.compute_ms)
    result = msgspec.structs.replace(result, compute_ms=statistics.median(times))
    if args.plot:
        from pfp_service.plot import plot_plan

        plot_plan(scenario, result, args.plot)
    if args.json:
        sys.stdout.write(msgspec.json.encode(result).decode() + "\n")
    else:
        print(summary(scenario.name, result, plot=args.plot))
    return 0
