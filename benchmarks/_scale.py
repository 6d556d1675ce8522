"""Fleet scale for ``pfp bench engine``: one tick of the live world, and how it grows.

One tick of 10,000 units x 1,000 threats through the raw kernel (every pair,
and culled) and through ``World.apply``, and a log-log grid of 100 to 10,000
units by 100 to 10,000 threats.
"""

from __future__ import annotations

import math
import statistics
import time
from typing import Any

import numpy as np


def median_ms(fn: Any, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


SCALE_SIZES = (100, 1_000, 10_000)
TARGET_TICK_MS = 20.0  # issue 10: one tick, 10,000 units x 1,000 threats, with culling
TARGET_GOALS_S = 1.0  # issue 10: 10,000 goals set, planner time in all
SCALE_LAYOUTS = {"spread": 30_000.0, "dense": 3_000.0}  # box side, metres; threats sigma 300 m x 210 m


def _scale_field(threats: int, box: float, seed: int) -> list[Any]:
    from pfp_service.wire import ThreatUpdate

    rng = np.random.default_rng(seed)
    return [
        ThreatUpdate(
            position=(float(x), float(y)),
            facing_deg=float(rng.uniform(0, 360)),
            sigma_range=300.0,
            sigma_lateral=210.0,
            skew=2.0,
        )
        for x, y in rng.uniform(0, box, (threats, 2))
    ]


def _cull_index() -> Any:
    """``core.cull.CullIndex`` where this tree has it, else ``None`` (the table then says so)."""
    try:
        from pfp_service.core.cull import CullIndex
    except ImportError:
        return None
    return CullIndex


def kernel_tick(units: int, threats: int, box: float, repeat: int, seed: int = 11) -> dict[str, Any]:
    """The raw descent kernel for ``units`` x ``threats``: every pair, and culled where culling exists."""
    from pfp_service.core import ThreatField
    from pfp_service.core.kernels import descent_many
    from pfp_service.world import translate

    rng = np.random.default_rng(seed)
    field = ThreatField(
        [translate.threat(u, f"t{j}") for j, u in enumerate(_scale_field(threats, box, seed))]
    )
    pts = rng.uniform(0, box, (units, 2))
    goals = rng.uniform(0, box, (units, 2))
    gains = np.full(units, 1e-3)
    out = np.empty((units, 4))
    descent_many(field.packed, pts, goals, gains, out)  # compile + warm
    reps = repeat if units * threats <= 1_000_000 else max(3, repeat // 7)
    res: dict[str, Any] = {
        "full_ms": median_ms(lambda: descent_many(field.packed, pts, goals, gains, out), reps)
    }
    cls = _cull_index()
    if cls is None:
        res.update(culled_ms=None, build_ms=None, fallback_units=None)
        return res
    t0 = time.perf_counter()
    index = cls(field.packed)
    res["build_ms"] = (time.perf_counter() - t0) * 1e3
    culled = np.empty((units, 4))
    res["fallback_units"] = index.descent(
        pts, goals, gains, culled
    )  # units the bound sent back to every threat
    res["culled_ms"] = median_ms(lambda: index.descent(pts, goals, gains, culled), reps)
    return res


def world_tick(units: int, threats: int, box: float, repeat: int, seed: int = 11) -> dict[str, Any]:
    """``World.apply`` as the node drives it (deliberation deferred): goals set, then ticks answering every unit.

    ``goals_s`` is one ``apply`` of every unit's first state and goal (parameters
    resolved, first directions, deliberation jobs asked); ``tick_ms`` the median
    ``apply`` of one state per unit after that, each unit moved one step along
    its last direction.  Jobs are not run: this is the reactive loop's cost.
    """
    from pfp_service.core import PlannerParams
    from pfp_service.node import gcpause
    from pfp_service.wire import Goal, UnitState
    from pfp_service.world.world import GoalSet, Input, StateReported, ThreatPut, World, WorldSettings

    rng = np.random.default_rng(seed)
    world = World(WorldSettings(planner=PlannerParams(), deliberation="deferred", unit_forget_s=None))
    world.apply([ThreatPut(f"t{j}", u) for j, u in enumerate(_scale_field(threats, box, seed))], 0.0)
    pos = rng.uniform(0, box, (units, 2))
    goals = rng.uniform(0, box, (units, 2))
    ids = [f"u{i}" for i in range(units)]
    first: list[Input] = [
        StateReported(u, UnitState(position=(float(x), float(y)), seq=0)) for u, (x, y) in zip(ids, pos)
    ]
    first += [GoalSet(u, Goal(position=(float(x), float(y)))) for u, (x, y) in zip(ids, goals)]
    t0 = time.perf_counter()
    with gcpause.paused():  # as the node's loop holds the collector off round each apply
        out = world.apply(first, 1.0)
    goals_s = time.perf_counter() - t0
    jobs = len(out.jobs)
    vec = {d.unit: d.vector for d in out.directions}
    step_m = 52.5  # the scale-free step here: a quarter of the narrowest sigma (210 m)
    times = []
    for k in range(max(3, repeat // 4)):
        for i, u in enumerate(ids):
            vx, vy = vec.get(u, (0.0, 0.0))
            pos[i, 0] += step_m * vx
            pos[i, 1] += step_m * vy
        batch: list[Input] = [
            StateReported(u, UnitState(position=(float(x), float(y)), seq=k + 1))
            for u, (x, y) in zip(ids, pos)
        ]
        t0 = time.perf_counter()
        with gcpause.paused():
            out = world.apply(batch, 2.0 + k)
        times.append((time.perf_counter() - t0) * 1e3)
        vec = {d.unit: d.vector for d in out.directions}
    return {"goals_s": goals_s, "jobs_asked": jobs, "tick_ms": statistics.median(times)}


def scale_table(repeat: int, quick: bool) -> dict[str, Any]:
    """One tick of 10,000 x 1,000 (kernel and ``World.apply``) per layout, and the log-log grid (spread)."""
    sizes = SCALE_SIZES[:2] if quick else SCALE_SIZES
    big_u, big_t = (1_000, 100) if quick else (10_000, 1_000)
    headline = {}
    for name, box in SCALE_LAYOUTS.items():
        headline[name] = {"units": big_u, "threats": big_t, **kernel_tick(big_u, big_t, box, repeat)}
        headline[name].update(world_tick(big_u, big_t, box, repeat))
    grid = []
    for nu in sizes:
        for nt in sizes:
            row = {"units": nu, "threats": nt, **kernel_tick(nu, nt, SCALE_LAYOUTS["spread"], repeat)}
            row.update(world_tick(nu, nt, SCALE_LAYOUTS["spread"], repeat))
            grid.append(row)
    return {"culling": _cull_index() is not None, "headline": headline, "grid": grid, "slopes": _slopes(grid)}


def _slopes(grid: list[dict[str, Any]]) -> dict[str, dict[str, float | None]]:
    """Log-log slope of each cost from the smallest to the largest count, the other count at its middle size."""
    by = {(r["units"], r["threats"]): r for r in grid}
    sizes = sorted({r["units"] for r in grid})
    lo, hi, mid = sizes[0], sizes[-1], sizes[len(sizes) // 2]
    out: dict[str, dict[str, float | None]] = {}
    for key in ("full_ms", "culled_ms", "tick_ms", "goals_s"):

        def slope(a: dict[str, Any], b: dict[str, Any]) -> float | None:
            if a.get(key) is None or b.get(key) is None or a[key] <= 0 or b[key] <= 0 or hi == lo:
                return None
            return math.log(b[key] / a[key]) / math.log(hi / lo)

        out[key] = {
            "units": slope(by[(lo, mid)], by[(hi, mid)]),
            "threats": slope(by[(mid, lo)], by[(mid, hi)]),
        }
    return out


def print_scale(sc: dict[str, Any]) -> None:
    print(
        f"\nfleet scale (threats sigma 300 x 210 m; culling {'on' if sc['culling'] else 'not in this tree'}):"
    )
    for name, h in sc["headline"].items():
        print(
            f"  one tick {h['units']:,} units x {h['threats']:,} threats, {name} "
            f"({SCALE_LAYOUTS[name] / 1000:g} km): kernel every pair {h['full_ms']:.1f} ms, "
            f"culled {_opt(h['culled_ms'])} ms (index {_opt(h['build_ms'])} ms, {h['fallback_units']} units fell back); "
            f"World.apply tick {h['tick_ms']:.1f} ms; goals set {h['goals_s']:.2f} s"
        )
    print(
        f"  log-log grid, spread layout: {'units':>6} {'threats':>7} {'every pair ms':>13} {'culled ms':>9} {'World tick ms':>13} {'goals s':>8}"
    )
    for r in sc["grid"]:
        print(
            f"  {'':28}{r['units']:>6} {r['threats']:>7} {r['full_ms']:>13.2f} {_opt(r['culled_ms']):>9} "
            f"{r['tick_ms']:>13.2f} {r['goals_s']:>8.3f}"
        )
    for key, sl in sc["slopes"].items():
        print(f"  slope of {key}: {_opt(sl['units'])} in units, {_opt(sl['threats'])} in threats")


def _opt(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"
