"""``pfp plan``: plan one scenario file and report the path and its quality.

``--planner pfp`` (default) is the potential-field planner with its trap
escapes; ``--planner optimal`` is the reference that minimises
``length + lambda * exposure`` on a fine 16-connected grid (every threat in
force from the start).  Both print the same JSON object.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from typing import Any

from pfp_service.cli._common import grid_cells, non_negative_float, positive_float, positive_int
from pfp_service.core.optimal import DEFAULT_CELLS, DEFAULT_LAMBDA
from pfp_service.core.params import ESCAPES


def register(sub: Any) -> None:
    p = sub.add_parser("plan", help="plan a scenario file (YAML or JSON)", description=__doc__)
    p.add_argument("scenario", help="scenario file (.yaml, .yml or .json)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a summary")
    p.add_argument("--plot", metavar="PNG", help="write threat contours, start, goal and path to PNG")
    p.add_argument(
        "--repeat", type=positive_int, default=1, metavar="N", help="compute_ms is the median of N runs"
    )
    p.add_argument("--delta", type=positive_float, help="override the goal weight delta")
    p.add_argument("--step", type=positive_float, help="override the step length (m)")
    p.add_argument("--tolerance", type=positive_float, help="override the arrival tolerance (m)")
    p.add_argument("--max-iter", type=positive_int, help="override the iteration limit")
    p.add_argument("--intensity", choices=("peak", "density"), help="override the intensity scale")
    p.add_argument("--escape", choices=ESCAPES, help="override the trap-escape strategy")
    p.add_argument(
        "--planner",
        choices=("pfp", "optimal"),
        default="pfp",
        help="potential field (default) or the grid optimum",
    )
    p.add_argument(
        "--lambda",
        dest="lam",
        type=non_negative_float,
        default=DEFAULT_LAMBDA,
        metavar="L",
        help=f"optimal planner: exposure weight in length + L * exposure (default {DEFAULT_LAMBDA:g})",
    )
    p.add_argument(
        "--cells",
        type=grid_cells,
        default=DEFAULT_CELLS,
        metavar="N",
        help=f"optimal planner: grid cells along the longer side (default {DEFAULT_CELLS})",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import msgspec

    from pfp_service.core import plan
    from pfp_service.core.optimal import plan_optimal
    from pfp_service.report import summary
    from pfp_service.scenario import load_scenario

    if args.plot:
        from pfp_service.plot import check_png_path

        check_png_path(args.plot, "--plot")
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
        if args.planner == "optimal":
            result = plan_optimal(
                scenario.start,
                scenario.goal,
                schedule,
                args.lam,
                params.intensity,
                scenario.bounds_tuple(),
                args.cells,
                time.perf_counter,
            )
        else:
            result = plan(
                scenario.start, scenario.goal, schedule, params, scenario.bounds_tuple(), time.perf_counter
            )
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
