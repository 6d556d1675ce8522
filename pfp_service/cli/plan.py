"""``pfp plan``: plan one scenario file and report the path and its quality.

``--planner pfp`` (default) is the potential-field planner with its trap
escapes; ``--planner optimal`` is the reference that minimises
``length + lambda * exposure`` on a fine 16-connected grid (every threat in
force from the start).  Both print the same JSON object.

Exit codes: 0 the goal was reached; 1 planned but not reached (trapped,
max_iter, out_of_bounds, invalid); 2 bad input (file or flag).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from typing import Any

from pfp_service.cli._common import (
    add_coords_arg,
    bounded_int,
    grid_cells,
    non_negative_float,
    positive_int,
)
from pfp_service.constraints import Delta, Step, Tolerance, flag_type
from pfp_service.core.options import DEFAULT_CELLS, ESCAPES, LAMBDA

# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"plan": "pfp plan examples/geo-simple.yaml --plot geo.png --coords mgrs"}


def register(sub: Any) -> None:
    p = sub.add_parser("plan", help="plan a scenario file (YAML or JSON)", description=__doc__)
    p.add_argument("scenario", help="scenario file (.yaml, .yml or .json)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a summary")
    p.add_argument(
        "--plot",
        metavar="PNG",
        help="write threat contours, start, goal and path to PNG (over terrain: hillshade, "
        "elevation contours and where each threat sees)",
    )
    p.add_argument(
        "--geojson",
        metavar="FILE",
        help="write path, threats and their zones as RFC 7946 GeoJSON (needs the scenario's origin or "
        "terrain; over terrain, points are [lon, lat, elevation])",
    )
    p.add_argument(
        "--zone-level",
        type=_share,
        default=0.1,
        metavar="F",
        help="--geojson: zone outline at this share of each threat's peak, 0 to 1 exclusive (default 0.1)",
    )
    add_coords_arg(p)
    p.add_argument(
        "--repeat", type=positive_int, default=1, metavar="N", help="compute_ms is the median of N runs"
    )
    p.add_argument("--intensity", choices=("peak", "density"), help="override the file's intensity scale")
    pf = p.add_argument_group(
        "potential-field planner only (--planner pfp); unset: the file's, else the scale-free rule"
    )
    # the bounds a scenario file's planner and a goal message have (constraints), for the same words
    pf.add_argument("--delta", type=flag_type(Delta, "a goal weight"), help="override the goal weight delta")
    pf.add_argument("--step", type=flag_type(Step, "a length in m"), help="override the step length (m)")
    pf.add_argument(
        "--tolerance", type=flag_type(Tolerance, "a length in m"), help="override the arrival tolerance (m)"
    )
    pf.add_argument(
        "--max-iter", type=bounded_int(1, MAX_ITER), help=f"override the iteration limit (1 to {MAX_ITER:,})"
    )
    pf.add_argument("--escape", choices=ESCAPES, help="override the trap-escape strategy")
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
        metavar="L",
        help=f"optimal planner: exposure weight in length + L * exposure (default {LAMBDA:g})",
    )
    p.add_argument(
        "--cells",
        type=grid_cells,
        metavar="N",
        help=f"optimal planner: grid cells along the longer side (default {DEFAULT_CELLS})",
    )
    p.add_argument(
        "--zones",
        metavar="GEOJSON",
        help="keep-out zones no path enters: RFC 7946 Polygons and MultiPolygons in lon/lat "
        "(needs the scenario's origin), added to the file's zones:",
    )
    p.add_argument(
        "--terrain",
        metavar="DEM",
        help="plan over this DEM (GeoTIFF, DTED, SRTM .hgt): threats masked by line of sight, slopes "
        "past the unit's class a barrier; overrides the file's terrain:",
    )
    p.add_argument(
        "--avoid-cores",
        action="store_const",
        const=True,
        help="optimal planner: never enter a threat core; trapped when no such route exists",
    )
    p.set_defaults(func=run)


# The same bound a scenario file's ``planner.max_iter`` has (``constraints.Iterations``).
MAX_ITER = 10_000_000
PFP_ONLY = ("delta", "step", "tolerance", "max_iter", "escape")
OPTIMAL_ONLY = ("lam", "cells", "avoid_cores")


def _share(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not 0.0 < v < 1.0:
        raise argparse.ArgumentTypeError(f"must be between 0 and 1 (exclusive), got {text!r}")
    return v


def _flag(dest: str) -> str:
    return "--lambda" if dest == "lam" else "--" + dest.replace("_", "-")


def check_flags(args: argparse.Namespace) -> None:
    """Refuse flags the chosen planner would ignore.

    Raises:
        InputError: naming the first such flag.
    """
    from pfp_service.errors import InputError

    unused, other = (OPTIMAL_ONLY, "optimal") if args.planner == "pfp" else (PFP_ONLY, "pfp")
    for dest in unused:
        if getattr(args, dest) is not None:
            raise InputError(_flag(dest), f"only goes with --planner {other}")


def exit_code(status: str) -> int:
    """0 when the goal was reached, 1 for any other plan status."""
    return 0 if status == "reached" else 1


def run(args: argparse.Namespace) -> int:
    import msgspec

    from pfp_service import plausible
    from pfp_service.coords import Coords
    from pfp_service.core.params import reach
    from pfp_service.errors import InputError
    from pfp_service.files import read_text
    from pfp_service.scenario import load_scenario
    from pfp_service.signals import interruptible

    check_flags(args)
    lam = LAMBDA if args.lam is None else args.lam
    cells = DEFAULT_CELLS if args.cells is None else args.cells
    if args.plot:
        from pfp_service.cli._common import require_extra
        from pfp_service.render import check_png_path

        require_extra("plot", "matplotlib")  # before planning, not after
        check_png_path(args.plot, "--plot")
    if args.geojson:
        from pfp_service.geojson import check_geojson_path

        check_geojson_path(args.geojson)
    read_text(args.scenario)  # a directory, binary, non-UTF-8 or huge file: one line naming it
    if args.terrain is not None:  # its header first: the scenario's threats load the compiled core
        from pfp_service.terrain.dem import check

        check(args.terrain)
    scenario = load_scenario(args.scenario)
    if args.terrain is None and scenario.terrain is not None:  # the file's own DEM, as light as --terrain's
        from pfp_service.terrain.dem import check

        check(scenario.terrain)
    for line in plausible.warnings(
        scenario.start,
        scenario.goal,
        [
            (t.id or f"t{i + 1}", t.sigma_range, t.sigma_lateral)
            for i, t in enumerate(scenario.threats)
            if t.sigma_range is not None and t.sigma_lateral is not None
        ],
        scenario.origin is not None,
    ):
        print(f"pfp plan: warning: {args.scenario}: {line}", file=sys.stderr)
    if args.coords in ("latlon", "mgrs") and scenario.origin is None:
        raise InputError(
            "--coords", f"{args.coords} needs an origin: add origin: {{lat: …, lon: …}} to {args.scenario}"
        )
    coords = Coords.choose(args.coords, scenario.origin)
    if args.geojson and scenario.origin is None and args.terrain is None and scenario.terrain is None:
        # over terrain the plane is placed at the DEM's centre, so the GeoJSON has an origin
        raise InputError("--geojson", f"{args.scenario} has no origin: add origin: {{lat: …, lon: …}}")
    params = scenario.planner.to_params().merged(
        delta=args.delta,
        step=args.step,
        tolerance=args.tolerance,
        max_iter=args.max_iter,
        intensity=args.intensity,
        escape=args.escape,
    )
    if args.planner == "pfp" and (problem := reach(params, scenario.start, scenario.goal)) is not None:
        raise InputError("--step" if args.step is not None else f"{args.scenario}: planner.step", problem)
    # Every file is read (and a hostile one refused) before the compiled core is imported: a refusal
    # stays light (issue 35).
    extra = []
    if args.zones:
        from pfp_service.geojson import load_zones

        extra = load_zones(args.zones, scenario.origin)
    from pfp_service.core import plan
    from pfp_service.core.optimal import plan_optimal
    from pfp_service.render import summary

    schedule = scenario.schedule()
    zones = scenario.zone_set()
    if args.zones:
        zones = zones.plus(extra)
    bounds = scenario.bounds_tuple()
    ground = None
    dem = args.terrain if args.terrain is not None else scenario.terrain
    if dem is not None:
        from pfp_service.terrain.planning import prepare

        points = [scenario.start, scenario.goal, *(s.threat.xi for s in schedule)]
        ground = prepare(dem, scenario.origin, points, bounds, scenario.unit.mobility())
        zones, bounds = zones.plus(ground.zones), ground.bounds
    sight = ground.sight if ground is not None else None

    def planned() -> list[Any]:
        """Every repeat's plan; on a worker thread, so Ctrl-C never lands inside a kernel (signals)."""
        results = []
        for _ in range(args.repeat):
            if args.planner == "optimal":
                result = plan_optimal(
                    scenario.start,
                    scenario.goal,
                    schedule,
                    lam,
                    params.intensity,
                    bounds,
                    cells,
                    time.perf_counter,
                    avoid_cores=bool(args.avoid_cores),
                    zones=zones,
                    sight=sight,
                )
            else:
                result = plan(
                    scenario.start,
                    scenario.goal,
                    schedule,
                    params,
                    bounds,
                    time.perf_counter,
                    zones=zones,
                    sight=sight,
                )
            results.append(result)
        return results

    results = interruptible(planned)
    result = results[-1]
    times = [r.compute_ms for r in results]
    result = msgspec.structs.replace(result, compute_ms=statistics.median(times))
    if ground is not None:
        from pfp_service.terrain.planning import profile

        result = msgspec.structs.replace(result, **profile(result, ground, schedule, params.intensity))
    if args.plot:
        from pfp_service.render import plot_plan

        plot_plan(scenario, result, args.plot, coords, zones=list(zones), terrain=ground)
    if args.geojson:
        from pfp_service import geojson

        elevation = ground.grid.elevation if ground is not None else None
        origin = ground.origin if ground is not None else scenario.origin
        collection = geojson.scenario_collection(scenario, result, args.zone_level, zones, origin, elevation)
        geojson.write(args.geojson, collection)
    if args.json:
        sys.stdout.write(msgspec.json.encode(result).decode() + "\n")
    else:
        print(summary(scenario.name, result, args.plot, coords, scenario.start, scenario.goal))
    return exit_code(result.status.value)
