"""What teams cost the world: World.apply CPU per state with and without teams, the same fleet in one run.

In process, no Zenoh: the same seeded fleet (units in fours: a lead, two followers, a robot) is
driven twice per round along the directions it gets, once with no teams and once with each four
a team (the lead scouting for the followers, the first follower controlling the lead and the
robot), and each tick's ``World.apply`` is timed with the process's CPU clock.  The figure is the
ratio, rounds alternating so both share the machine's noise; the issue's target (1.2x) is for
``pfp bench service``, whose CPU per state also pays for decoding and Zenoh.

``--terrain``: the controller's link over the Jacksboro DEM in seeded runs instead
(``benchmarks/_teams_terrain.py``): each robot's link as a share of the mission, every outage
with its cause, and whether each team arrived.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import time
from typing import Any

from pfp_service.argtypes import positive_int

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--units", type=positive_int, default=1000, help="units, in fours (default 1000)")
    p.add_argument(
        "--ticks", type=positive_int, default=20, help="reports of every unit per run (default 20)"
    )
    p.add_argument("--rounds", type=positive_int, default=3, help="runs of each, alternating (default 3)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.add_argument(
        "--terrain",
        action="store_true",
        help="instead: the controller's link over the Jacksboro DEM in seeded runs (link %%, outages, arrivals)",
    )
    p.add_argument("--seeds", type=positive_int, default=10, help="--terrain: seeded runs (default 10)")


def measure(units: int, ticks: int, teams: bool, seed: int = 7) -> dict[str, float]:
    """One run: CPU microseconds per state, and how many of the last directions a team rewrote."""
    from pfp_service.core import PlannerParams
    from pfp_service.wire import Goal, ThreatUpdate, UnitState
    from pfp_service.wire.messages import TeamUpdate
    from pfp_service.world.events import Input
    from pfp_service.world.world import GoalSet, StateReported, TeamPut, ThreatPut, World, WorldSettings

    rng = random.Random(seed)
    w = World(WorldSettings(planner=PlannerParams(intensity="density", step=1.0)))
    threats = [
        ThreatUpdate(position=(rng.uniform(200, 1800), rng.uniform(0, 4000)), facing_deg=270.0,
                     sigma_range=30.0, sigma_lateral=20.0)
        for _ in range(20)
    ]  # fmt: skip
    w.apply([ThreatPut(f"t{i}", t) for i, t in enumerate(threats)], 0.0)
    at: dict[str, tuple[float, float]] = {}
    for k in range(units // 4):
        y = 16.0 * k
        at |= {f"r{k}": (40.0, y), f"m{k}a": (0.0, y), f"m{k}b": (-10.0, y + 4), f"r{k}x": (20.0, y + 8)}
    w.apply([StateReported(u, UnitState(position=p, speed_mps=0.0)) for u, p in at.items()], 0.0)
    if teams:
        w.apply(
            [
                TeamPut(f"g{k}", TeamUpdate(lead=f"r{k}", follow=[f"m{k}a", f"m{k}b"], standoff_m=40.0,
                        corridor_m=8.0, controller=f"m{k}a", robots=[f"r{k}", f"r{k}x"], radio_range_m=300.0))
                for k in range(units // 4)
            ],
            0.0,
        )  # fmt: skip
    out = w.apply([GoalSet(u, Goal(position=(2000.0, p[1]))) for u, p in at.items()], 0.0)
    last = {d.unit: d for d in out.directions}
    cpu, states = 0.0, 0
    for t in range(1, ticks + 1):
        for u, p in at.items():
            d = last.get(u)
            if d is not None and d.reach_m is not None:
                run_m = min(2.0, d.reach_m)  # 2 m a report, no further than the direction holds
                at[u] = (p[0] + d.vector[0] * run_m, p[1] + d.vector[1] * run_m)
        batch: list[Input] = [StateReported(u, UnitState(position=p, speed_mps=2.0)) for u, p in at.items()]
        c0 = time.process_time()
        out = w.apply(batch, float(t))
        cpu += time.process_time() - c0
        states += len(batch)
        last.update({d.unit: d for d in out.directions})
    judged = sum(1 for d in last.values() if d.reason.startswith("team "))
    return {"us_per_state": cpu / states * 1e6, "judged": float(judged)}


def run(args: argparse.Namespace) -> int:
    if args.terrain:
        from benchmarks._teams_terrain import measure_terrain, print_terrain

        fig_t = measure_terrain(args.seeds)
        if args.json:
            print(json.dumps(fig_t))
        else:
            print_terrain(fig_t)
        return 0
    units = max(4, args.units // 4 * 4)
    measure(units, 2, False)  # warm: the compiled kernels, the caches
    measure(units, 2, True)
    plain: list[float] = []
    teamed: list[float] = []
    judged = 0.0
    for _ in range(args.rounds):
        plain.append(measure(units, args.ticks, False)["us_per_state"])
        got = measure(units, args.ticks, True)
        teamed.append(got["us_per_state"])
        judged = got["judged"]
    ratios = [b / a for a, b in zip(plain, teamed)]
    fig: dict[str, Any] = {
        "units": units,
        "teams": units // 4,
        "ticks": args.ticks,
        "no_teams_us_per_state": [round(x, 1) for x in plain],
        "teams_us_per_state": [round(x, 1) for x in teamed],
        "ratio_median": round(statistics.median(ratios), 2),
        "last_directions_judged": int(judged),
        "loadavg": list(os.getloadavg()),
    }
    if args.json:
        print(json.dumps(fig))
        return 0
    print(f"{units} units, {units // 4} teams of 4, {args.ticks} reports each, load {fig['loadavg'][0]:.2f}")
    for i, (a, b) in enumerate(zip(plain, teamed)):
        print(f"round {i + 1}: no teams {a:.1f} us/state, teams {b:.1f} us/state, x{b / a:.2f}")
    print(
        f"median ratio x{fig['ratio_median']:.2f}; {int(judged)} of the last directions rewritten by a team"
    )
    return 0
