"""Engine speed: the paper's Table 3 grid against its MATLAB figures and an as-published Python baseline.

Every row runs exactly MAXITER descent steps (the work the paper timed: its
times grow with MAXITER), for our planner and for the baseline alike, on the
same scenario.  Ours is timed end to end through ``plan()``: stepper, trap
bookkeeping and path metrics included.  More figures: a natural 300-step,
8-threat plan; one vectorised call stepping 10,000 units against 100
threats; and fleet scale -- one tick of 10,000 units x 1,000 threats through
the raw kernel (every pair, and culled) and through ``World.apply``, with a
log-log grid of 100 to 10,000 units by 100 to 10,000 threats; and a
platoon of 200 units with one objective, its route searches shared
(``core.routes``) against one search per unit; and the goal storm's
look-aheads and the contingency wave of ``pfp bench service``, in process
(``bench._deliberation``).
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from benchmarks._check import add_check_arg, exit_code
from benchmarks._deliberation import (
    STORM_UNITS,
    TARGET_LOOKAHEAD_MS,
    TARGET_WAVE_MS,
    print_storm_and_wave,
    storm_and_wave,
)
from benchmarks._scale import TARGET_GOALS_S, TARGET_TICK_MS, print_scale, scale_table
from benchmarks._scale import median_ms as _median_ms
from pfp_service.argtypes import positive_int

# Table 3 of the paper: (MAXITER, size, threats) -> seconds, with its delta and step per size.
PAPER_SECONDS: dict[tuple[int, int, int], float] = {
    (300, 10, 2): 1.760, (300, 10, 4): 2.609, (300, 20, 4): 2.931,
    (300, 20, 6): 3.832, (300, 30, 6): 5.117, (300, 30, 8): 5.488,
    (500, 10, 2): 2.273, (500, 10, 4): 3.421, (500, 20, 4): 3.642,
    (500, 20, 6): 4.679, (500, 30, 6): 5.329, (500, 30, 8): 6.909,
    (1000, 10, 2): 3.306, (1000, 10, 4): 4.918, (1000, 20, 4): 5.087,
    (1000, 20, 6): 6.760, (1000, 30, 6): 8.171, (1000, 30, 8): 11.302,
}  # fmt: skip
PAPER_DELTA_STEP = {10: (0.08, 0.1), 20: (0.3, 0.2), 30: (0.7, 0.3)}
TARGET_VS_PAPER = 1000.0
TARGET_VS_BASELINE = 50.0
TARGET_PATH_MS = 2.0
TARGET_FLEET_MS = 20.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--repeat", type=positive_int, default=21, help="runs per row for our median (default 21)")
    p.add_argument(
        "--baseline-repeat", type=positive_int, default=3, help="runs per row for the baseline median"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--quick", action="store_true", help="only MAXITER 300 rows and a small scale grid (a smoke run)"
    )
    p.add_argument("--no-scale", action="store_true", help="skip the fleet-scale tick and log-log grid")
    p.add_argument("--scale-only", action="store_true", help="only the fleet-scale tick and log-log grid")
    p.add_argument(
        "--no-deliberation",
        action="store_true",
        help="skip the goal storm's look-aheads and the contingency wave (in process, 1,000 units)",
    )
    p.add_argument(
        "--deliberation-only",
        action="store_true",
        help="only the goal storm's look-aheads and the contingency wave (about a minute)",
    )
    add_check_arg(p)


def table_threats(size: int, count: int) -> list[Any]:
    """The threat layout for one row: Table 1's for 10x10 with 2, else seeded and spread along the route."""
    from pfp_service.core import Threat

    sr, sl = 0.1 * size, 0.07 * size
    if (size, count) == (10, 2):
        spots = [(4.0, 6.0), (7.0, 3.0)]
    else:
        rng = np.random.default_rng(1000 * size + count)
        spots = []
        for k in range(count):
            along = size * (0.2 + 0.6 * (k + rng.random()) / count)
            off = rng.uniform(0.12, 0.3) * size * (1 if k % 2 else -1)
            spots.append((along + off / math.sqrt(2), along - off / math.sqrt(2)))
    return [Threat.from_facing(p, 225.0, sr, sl, 2.0, 1.0, f"e{i + 1}") for i, p in enumerate(spots)]


@dataclass
class Row:
    max_iter: int
    size: int
    threats: int
    delta: float
    step: float
    steps_run: int
    ours_ms: float
    paper_ms: float
    baseline_ms: float
    vs_paper: float
    vs_baseline: float


def _fixed_params(delta: float, step: float, iterations: int) -> Any:
    from pfp_service.core import Resolved

    # a negative tolerance (never arrived, so no final approach onto the goal either) and detection
    # windows past MAXITER: exactly `iterations` steps, like the paper's timing runs
    return Resolved(delta, step, iterations, -1.0, "density", "none", iterations + 1, iterations + 1, 0)


def run_rows(repeat: int, baseline_repeat: int, quick: bool) -> list[Row]:
    from benchmarks._baseline import baseline_path
    from pfp_service.core import Scheduled, plan

    rows = []
    for (k, size, n), paper_s in PAPER_SECONDS.items():
        if quick and k != 300:
            continue
        delta, step = PAPER_DELTA_STEP[size]
        threats = table_threats(size, n)
        sched = [Scheduled(t) for t in threats]
        params = _fixed_params(delta, step, k)
        goal = (float(size), float(size))
        result = plan((0.0, 0.0), goal, sched, params)
        plan((0.0, 0.0), goal, sched, params)  # warm
        ours = _median_ms(lambda: plan((0.0, 0.0), goal, sched, params), repeat)
        base = _median_ms(lambda: baseline_path((0, 0), goal, threats, delta, step, k), baseline_repeat)
        rows.append(
            Row(
                k,
                size,
                n,
                delta,
                step,
                result.steps,
                ours,
                paper_s * 1e3,
                base,
                paper_s * 1e3 / ours,
                base / ours,
            )
        )
    return rows


def natural_path_ms(repeat: int) -> dict[str, Any]:
    """A real plan (stops on arrival) through 8 threats, sized to take about 300 steps."""
    from pfp_service.core import PlannerParams, Scheduled, plan

    threats = table_threats(30, 8)
    sched = [Scheduled(t) for t in threats]
    goal = (30.0, 30.0)
    params = PlannerParams(delta=0.7, step=0.15, max_iter=1000, tolerance=0.15, intensity="density")
    r = plan((0.0, 0.0), goal, sched, params)
    ms = _median_ms(lambda: plan((0.0, 0.0), goal, sched, params), repeat)
    return {
        "status": r.status.value,
        "steps": r.steps,
        "threats": 8,
        "median_ms": ms,
        "target_ms": TARGET_PATH_MS,
    }


def fleet_ms(repeat: int) -> dict[str, Any]:
    """One vectorised kernel call for 10,000 units against 100 threats; plus full advise_many."""
    from pfp_service.core import Threat, ThreatField, resolve
    from pfp_service.core.batch import advise_many
    from pfp_service.core.kernels import batch_descent
    from pfp_service.core.params import PlannerParams
    from pfp_service.core.stepper import Stepper

    rng = np.random.default_rng(7)
    out: dict[str, Any] = {"units": 10_000, "threats": 100, "target_ms": TARGET_FLEET_MS}
    for layout, box, sigma in (("spread", 30_000.0, 600.0), ("dense", 3_000.0, 600.0)):
        threats = [
            Threat.from_facing(
                tuple(rng.uniform(0, box, 2)), rng.uniform(0, 360), sigma, 0.7 * sigma, 2.0, 1.0, f"t{j}"
            )
            for j in range(100)
        ]
        field = ThreatField(threats)
        pts = rng.uniform(0, box, (10_000, 2))
        goals = rng.uniform(0, box, (10_000, 2))
        gains = np.full(10_000, 1e-6)
        res = np.empty((10_000, 4))
        batch_descent(field.packed, pts, goals, gains, res)  # compile + warm
        out[f"{layout}_kernel_ms"] = _median_ms(
            lambda: batch_descent(field.packed, pts, goals, gains, res), repeat
        )
        # steady state: plain descent (auto's look-ahead runs once per goal or world change, timed below)
        params = resolve(PlannerParams(escape="none"), (0.0, 0.0), (box, box), threats)
        steppers = [Stepper(tuple(p), tuple(g), params) for p, g in zip(pts, goals)]
        advise_many(steppers, field, pts)
        out[f"{layout}_advise_many_ms"] = _median_ms(
            lambda: advise_many(steppers, field, pts), max(3, repeat // 4)
        )
        # auto's one-off look-ahead when a goal is set: per unit, over the first 40 units
        params = resolve(PlannerParams(escape="auto"), (0.0, 0.0), (box, box), threats)
        per_unit = []
        for p, g in zip(pts[:40], goals[:40]):
            s = Stepper(tuple(p), tuple(g), params)
            t0 = time.perf_counter()
            s.advise(field, float(p[0]), float(p[1]))
            per_unit.append((time.perf_counter() - t0) * 1e3)
        out[f"{layout}_foresight_ms_per_unit"] = statistics.median(per_unit)
    return out


# -- shared route searches: a platoon with one objective ----------------------------------
PLATOON_UNITS = 200


def platoon_routes(units: int = PLATOON_UNITS, seed: int = 5) -> dict[str, Any]:
    """A platoon within 300 m, one objective 3.9 km off through 60 threats: its route searches, shared and not.

    Every unit asks ``global_route`` (what ``auto``'s look-ahead asks when
    descent is foreseen to be trapped), once with one search per unit
    (``RouteCache(max_entries=0)``: as before routes were shared), once through
    a fresh shared cache, and once more after a world change (a new field, the
    same threats: the goal is then known to be shared).  ``cost_ratio``: each
    shared route's ``J`` over the unit's own search's, worst and median.
    """
    from pfp_service.core import PlannerParams, Threat, ThreatField, resolve
    from pfp_service.core.escape import Escaper
    from pfp_service.core.escape_strategies import NoCandidate, global_route
    from pfp_service.core.metrics import path_cost
    from pfp_service.core.routes import RouteCache

    rng = np.random.default_rng(seed)
    threats = [
        Threat.from_facing(
            tuple(rng.uniform(0, 3000, 2)), rng.uniform(0, 360), 300.0, 210.0, 2.0, 1.0, f"t{j}"
        )
        for j in range(60)
    ]
    goal = (2900.0, 2900.0)
    pos = rng.uniform(100.0, 400.0, (units, 2))
    params = resolve(PlannerParams(escape="auto"), (250.0, 250.0), goal, threats)

    def traps(field: Any) -> list[Any]:
        out = []
        for key, (x, y) in enumerate(pos.tolist(), start=1):
            esc = Escaper(params, goal, params.delta / ((goal[0] - x) ** 2 + (goal[1] - y) ** 2), None, key)
            out.append(esc._trap(field, x, y))
        return out

    def run(cache: Any, field: Any) -> tuple[dict[str, Any], list[Any]]:
        trs = traps(field)
        before = cache.stats().searches
        t0 = time.perf_counter()
        polys = [global_route(tr, cache) for tr in trs]
        total = time.perf_counter() - t0
        return {
            "searches": cache.stats().searches - before,
            "total_s": total,
            "ms_per_unit": total * 1e3 / units,
            "no_route": sum(isinstance(p, NoCandidate) for p in polys),
        }, polys

    field = ThreatField(threats)
    own, mine = run(RouteCache(max_entries=0), field)
    cache = RouteCache()
    first, ours = run(cache, field)
    again, _ = run(cache, ThreatField(threats))
    ratios = [
        path_cost(b, field) / path_cost(a, field)
        for a, b in zip(mine, ours)
        if not isinstance(a, NoCandidate) and not isinstance(b, NoCandidate)
    ]
    st = cache.stats()
    return {
        "units": units,
        "threats": len(threats),
        "one_search_per_unit": own,
        "shared_first_sight": first,
        "shared_after_world_change": again,
        "speedup": own["total_s"] / first["total_s"],
        "speedup_after_world_change": own["total_s"] / again["total_s"],
        "cost_ratio_max": max(ratios, default=math.nan),
        "cost_ratio_median": statistics.median(ratios) if ratios else math.nan,
        "kept_grids": st.entries,
        "kept_nodes": st.nodes,
    }


def _searches(n: int) -> str:
    return f"{n} search" if n == 1 else f"{n} searches"


def _print_platoon(pl: dict[str, Any]) -> None:
    own, first, again = pl["one_search_per_unit"], pl["shared_first_sight"], pl["shared_after_world_change"]
    print(
        f"\nplatoon of {pl['units']} units, one objective ({pl['threats']} threats): route searches and time\n"
        f"  one search per unit: {_searches(own['searches'])}, {own['total_s']:.2f} s ({own['ms_per_unit']:.1f} ms a unit)\n"
        f"  shared, first sight: {_searches(first['searches'])}, {first['total_s']:.2f} s ({first['ms_per_unit']:.1f} ms a unit), "
        f"{pl['speedup']:.1f}x faster\n"
        f"  shared, after a world change: {_searches(again['searches'])}, {again['total_s']:.2f} s "
        f"({again['ms_per_unit']:.1f} ms a unit), {pl['speedup_after_world_change']:.1f}x faster\n"
        f"  J of a shared route over the unit's own: median {pl['cost_ratio_median']:.3f}, worst {pl['cost_ratio_max']:.3f}; "
        f"kept {pl['kept_grids']} grids, {pl['kept_nodes']:,} nodes"
    )


def run(args: argparse.Namespace) -> int:
    import numba

    machine = (
        f"{platform.machine()}, {platform.processor() or 'cpu'}, numba threads {numba.get_num_threads()}"
    )
    if args.deliberation_only:
        alone = storm_and_wave(100 if args.quick else STORM_UNITS)
        mean = alone["lookahead_cpu_ms"]["mean"]
        only = {
            "goal storm: look-aheads' mean worker CPU <= 4 ms": mean is not None
            and mean <= TARGET_LOOKAHEAD_MS,
            "contingency wave, 1,000 units: World.apply <= 10 ms": alone["wave"]["apply_ms_median"]
            <= TARGET_WAVE_MS,
        }
        if args.json:
            print(json.dumps({"machine": machine, "deliberation": alone, "checks": only}, indent=2))
        else:
            print_storm_and_wave(alone)
            print()
            for name, ok in only.items():
                print(f"  [{'ok' if ok else 'MISSED'}] {name}")
        return exit_code(only.values(), args.check)
    if args.scale_only:
        only = scale_table(args.repeat, args.quick)
        if args.json:
            print(json.dumps({"machine": machine, "scale": only}, indent=2))
        else:
            print_scale(only)
        return 0
    rows = run_rows(args.repeat, args.baseline_repeat, args.quick)
    path = natural_path_ms(args.repeat)
    fleet = fleet_ms(args.repeat)
    platoon = platoon_routes(50 if args.quick else PLATOON_UNITS)
    scale = None if args.no_scale else scale_table(args.repeat, args.quick)
    delib = None if args.no_deliberation else storm_and_wave(100 if args.quick else STORM_UNITS)
    checks = {
        "every row >= 1000x the paper": all(r.vs_paper >= TARGET_VS_PAPER for r in rows),
        "every row >= 50x the baseline": all(r.vs_baseline >= TARGET_VS_BASELINE for r in rows),
        "300-step 8-threat path <= 2 ms": path["median_ms"] <= TARGET_PATH_MS,
        "10,000 units x 100 threats <= 20 ms (dense kernel call)": fleet["dense_kernel_ms"]
        <= TARGET_FLEET_MS,
        "a platoon with one objective: <= 2 route searches, 1 after a world change": platoon[
            "shared_first_sight"
        ]["searches"]
        <= 2
        and platoon["shared_after_world_change"]["searches"] == 1,
    }
    if scale is not None and not args.quick:
        h = scale["headline"]["spread"]
        tick = h["culled_ms"] if h["culled_ms"] is not None else h["full_ms"]
        checks["one tick 10,000 x 1,000 <= 20 ms (spread, culled kernel)"] = tick <= TARGET_TICK_MS
        checks["one World.apply tick 10,000 x 1,000 <= 20 ms (spread)"] = h["tick_ms"] <= TARGET_TICK_MS
        checks["10,000 goals set <= 1 s (spread)"] = h["goals_s"] <= TARGET_GOALS_S
    if delib is not None and not args.quick:
        mean = delib["lookahead_cpu_ms"]["mean"]
        checks["goal storm: look-aheads' mean worker CPU <= 4 ms"] = (
            mean is not None and mean <= TARGET_LOOKAHEAD_MS
        )
        checks["contingency wave, 1,000 units: World.apply <= 10 ms"] = (
            delib["wave"]["apply_ms_median"] <= TARGET_WAVE_MS
        )
    if args.json:
        doc = {
            "machine": machine,
            "rows": [asdict(r) for r in rows],
            "path": path,
            "fleet": fleet,
            "platoon": platoon,
            "scale": scale,
            "deliberation": delib,
            "checks": checks,
        }
        print(json.dumps(doc, indent=2))
        return exit_code(checks.values(), args.check)
    print(f"pfp bench engine on {machine}")
    print("each row: exactly MAXITER steps, density intensity, the paper's delta and step per size\n")
    head = f"{'MAXITER':>7} {'size':>6} {'thr':>3} {'ours ms':>9} {'paper ms':>9} {'baseline ms':>12} {'x paper':>9} {'x baseline':>10}"
    print(head)
    print("-" * len(head))
    for r in rows:
        print(
            f"{r.max_iter:>7} {r.size:>3}x{r.size:<2} {r.threats:>3} {r.ours_ms:>9.3f} {r.paper_ms:>9.0f} "
            f"{r.baseline_ms:>12.1f} {r.vs_paper:>9.0f} {r.vs_baseline:>10.0f}"
        )
    print(
        f"\nnatural plan, 8 threats: {path['status']} in {path['steps']} steps, median {path['median_ms']:.3f} ms"
    )
    print(
        "10,000 units x 100 threats, one batch_descent call: "
        f"spread {fleet['spread_kernel_ms']:.2f} ms, dense {fleet['dense_kernel_ms']:.2f} ms; "
        f"full advise_many (with per-unit bookkeeping): spread {fleet['spread_advise_many_ms']:.1f} ms, "
        f"dense {fleet['dense_advise_many_ms']:.1f} ms"
    )
    print(
        "escape auto look-ahead, once per goal or world change, median per unit: "
        f"spread {fleet['spread_foresight_ms_per_unit']:.2f} ms, dense {fleet['dense_foresight_ms_per_unit']:.2f} ms"
    )
    _print_platoon(platoon)
    if scale is not None:
        print_scale(scale)
    if delib is not None:
        print_storm_and_wave(delib)
    print()
    for name, ok in checks.items():
        print(f"  [{'ok' if ok else 'MISSED'}] {name}")
    return exit_code(checks.values(), args.check)
