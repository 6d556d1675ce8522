"""``pfp bench teams --terrain``: the controller's link over real ground in seeded runs (issue 33).

In process, no Zenoh: the live ``World`` over the Jacksboro DEM (``tests/terrain_data.py``; the
scenarios of ``tests/terrain_scenarios.py``, as ``pfp bench terrain_routes``), inline deliberation.
Per seed one team crosses from the scenario's start to its goal: a robot ``r1`` leads and scouts,
the manned ``m1`` follows on the ground it cleared and controls it, and a second robot ``r2`` on
its own route is controlled by ``m1`` too.  The scenario's threats appear once the lead has come a
third of the way.  Each unit reports every ``DT_S`` and drives along its last direction at its
speed, no further than the direction holds.

The link is judged here, not by the planner: after each move, a robot is linked when it is within
the radio range of its controller and the sight line between the two mast tops (the planner's
unit height above the ground) clears every sample of the ground taken every tenth of a cell along
it, the ground interpolated by scipy's ``RegularGridInterpolator`` (not the planner's
``link_sight``).  The share is of the mission's reports (until the whole team has arrived, or the
cap); each outage is reported with its cause (range or sight, and what the robot's last direction
said).
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["measure_terrain", "print_terrain"]

DT_S = 5.0  # seconds between reports
SPEED_MPS = {"r1": 4.0, "m1": 3.0, "r2": 4.0}
RADIO_RANGE_M = 1500.0
STANDOFF_M = 300.0
CORRIDOR_M = 40.0
TARGET_LINK_PCT = 99.0
_SIGHT_SAMPLES_PER_CELL = 10


def _sight_checker(grid: Any, mast_m: float) -> Any:
    """``linked(a, b)``: whether two mast tops see each other over ``grid``'s ground (scipy's interpolation)."""
    from scipy.interpolate import RegularGridInterpolator

    ny, nx = grid.z.shape
    xs = grid.x0_m + np.arange(nx) * grid.cell_m
    ys = grid.y0_m + np.arange(ny) * grid.cell_m
    ground = RegularGridInterpolator((ys, xs), np.asarray(grid.z, dtype=float), bounds_error=False)

    def blocked_at(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float] | None:
        n = max(2, math.ceil(math.dist(a, b) / grid.cell_m * _SIGHT_SAMPLES_PER_CELL) + 1)
        f = np.linspace(0.0, 1.0, n)
        px, py = a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f
        z = ground(np.column_stack([py, px]))
        line = (z[0] + mast_m) + ((z[-1] + mast_m) - (z[0] + mast_m)) * f
        over = np.flatnonzero(z[1:-1] > line[1:-1])
        if len(over) == 0:
            return None
        k = over[0] + 1
        return float(px[k]), float(py[k])

    return blocked_at


def _update(threat: Any) -> Any:
    """The wire's put of a skew-normal ``core.Threat`` built by ``Threat.from_facing``: its facing, sigmas, skew."""
    from pfp_service.wire import ThreatUpdate

    vals, vecs = np.linalg.eigh(np.asarray(threat.omega, dtype=float))
    sr, sl = math.sqrt(vals[1]), math.sqrt(vals[0])
    d = vecs[:, 1]
    w = np.sqrt(np.diag(np.asarray(threat.omega, dtype=float)))
    pull = w * d / sr  # alpha = skew * pull, for d pointing the way the threat faces
    alpha = np.asarray(threat.alpha, dtype=float)
    if float(alpha @ pull) < 0.0:
        d, pull = -d, -pull
    skew = float(np.linalg.norm(alpha)) / max(float(np.linalg.norm(pull)), 1e-12)
    facing = math.degrees(math.atan2(d[0], d[1])) % 360.0
    return ThreatUpdate(
        position=threat.xi,
        facing_deg=facing,
        sigma_range=sr,
        sigma_lateral=sl,
        skew=skew,
        weight=threat.weight,
    )


def _mover(before: dict[str, Any], at: dict[str, Any], robot: str, blocked_at: Any) -> str:
    """Which move hid the robot: the controller's (its old place still sees the robot's new one), the robot's, or both."""
    if blocked_at(before["m1"], before[robot]) is not None:
        return "already hidden"
    if blocked_at(before["m1"], at[robot]) is None:
        return "after the controller's step"
    if blocked_at(at["m1"], before[robot]) is None:
        return "after the robot's step"
    return "after both steps"


def _team_run(ground: Any, start: Any, goal: Any, sched: Any, seed: int, blocked_at: Any) -> dict[str, Any]:
    from pfp_service.core import PlannerParams
    from pfp_service.wire import Goal, UnitState
    from pfp_service.wire.messages import TeamUpdate
    from pfp_service.world.world import GoalSet, StateReported, TeamPut, ThreatPut, World, WorldSettings

    w = World(
        WorldSettings(
            planner=PlannerParams(intensity="density"),
            terrain=ground,
            bounds=ground.bounds,
            deliberation="inline",
        )
    )
    ux, uy = (goal[0] - start[0]), (goal[1] - start[1])
    far = math.hypot(ux, uy)
    ux, uy = ux / far, uy / far
    at = {
        "r1": start,
        "m1": (start[0] - 60.0 * ux, start[1] - 60.0 * uy),
        "r2": (start[0] - 60.0 * ux + 80.0 * uy, start[1] - 60.0 * uy - 80.0 * ux),
    }
    team = TeamUpdate(
        lead="r1",
        follow=["m1"],
        standoff_m=STANDOFF_M,
        corridor_m=CORRIDOR_M,
        controller="m1",
        robots=["r1", "r2"],
        radio_range_m=RADIO_RANGE_M,
    )
    w.apply([StateReported(u, UnitState(position=p, speed_mps=0.0)) for u, p in at.items()], 0.0)
    w.apply([TeamPut("alpha", team)], 0.0)
    out = w.apply([GoalSet(u, Goal(position=goal, tolerance=100.0)) for u in at], 0.0)
    last = {d.unit: d for d in out.directions}
    cap = int(3.0 * far / min(SPEED_MPS.values()) / DT_S)
    threats_in = False
    reports = {r: 0 for r in ("r1", "r2")}
    linked = {r: 0 for r in ("r1", "r2")}
    outages: list[dict[str, Any]] = []
    open_: dict[str, dict[str, Any]] = {}
    arrived: set[str] = set()
    ticks = 0
    for tick in range(1, cap + 1):
        ticks = tick
        t = tick * DT_S
        before = dict(at)
        for u, p in at.items():
            d = last.get(u)
            run = 0.0 if d is None or d.reach_m is None else min(SPEED_MPS[u] * DT_S, d.reach_m)
            v = d.vector if d is not None else (0.0, 0.0)
            at[u] = (p[0] + v[0] * run, p[1] + v[1] * run)
        batch: list[Any] = []
        if not threats_in and math.dist(at["r1"], start) >= far / 3.0:
            threats_in = True  # the contingency: the threats appear mid-route
            batch += [ThreatPut(s.threat.id or f"t{k}", _update(s.threat)) for k, s in enumerate(sched)]
        batch += [StateReported(u, UnitState(position=p, speed_mps=SPEED_MPS[u])) for u, p in at.items()]
        out = w.apply(batch, t)
        last.update({d.unit: d for d in out.directions})
        arrived |= {u for u, d in last.items() if d.status.value == "arrived"}
        for r in ("r1", "r2"):
            reports[r] += 1
            c, p = at["m1"], at[r]
            far_m = math.dist(c, p)
            cause = None
            if far_m > RADIO_RANGE_M:
                cause = f"range: {far_m:,.0f} m"
            elif (hit := blocked_at(c, p)) is not None:
                cause = f"sight: ground at ({hit[0]:,.0f}, {hit[1]:,.0f}) above the line, {_mover(before, at, r, blocked_at)}"
            if cause is None:
                linked[r] += 1
                if r in open_:
                    outages.append(open_.pop(r) | {"until_s": t})
            elif r not in open_:
                said = last.get(r)
                open_[r] = {"robot": r, "from_s": t, "cause": cause, "said": said.reason if said else ""}
        if arrived >= set(at):
            break
    outages += [o | {"until_s": None} for o in open_.values()]
    return {
        "seed": seed,
        "reports": ticks,
        "link_pct": {r: 100.0 * linked[r] / max(1, reports[r]) for r in reports},
        "arrived": sorted(arrived),
        "all_arrived": arrived >= set(at),
        "outages": outages,
        "reasons": {u: (d.status.value, d.reason) for u, d in last.items()},
    }


def measure_terrain(seeds: int) -> dict[str, Any]:
    """Each seed's link share per robot, its outages and which units arrived; or ``{"not_run": why}``."""
    from benchmarks.terrain_routes import _checkout

    got = _checkout()
    if isinstance(got, str):
        return {"not_run": got}
    terrain_data, scenarios = got
    from pfp_service.terrain.live import load

    rows = []
    with tempfile.TemporaryDirectory(prefix="pfp-bench-teams-") as tmp:
        dem = str(terrain_data.write_geographic(Path(tmp) / "jacksboro.tif"))
        ground = load(dem, None, None, "foot")
        blocked_at = _sight_checker(ground.grid, ground.unit.height_m)
        for seed in range(seeds):
            start, goal, sched = scenarios.scenario(ground.grid, seed)
            rows.append(_team_run(ground, start, goal, sched, seed, blocked_at))
    pcts = [p for row in rows for p in row["link_pct"].values()]
    return {
        "seeds": seeds,
        "rows": rows,
        "link_pct_min": min(pcts),
        "link_pct_mean": sum(pcts) / len(pcts),
        "all_arrived": sum(row["all_arrived"] for row in rows),
        "outages": sum(len(row["outages"]) for row in rows),
        "target_pct": TARGET_LINK_PCT,
        "loadavg": list(os.getloadavg()),
    }


def print_terrain(fig: dict[str, Any]) -> None:
    if "not_run" in fig:
        print(f"not run: {fig['not_run']}")
        return
    print(f"{fig['seeds']} seeded runs over the Jacksboro DEM, load {fig['loadavg'][0]:.2f}")
    for row in fig["rows"]:
        links = ", ".join(f"{r} {p:.1f} %" for r, p in row["link_pct"].items())
        print(
            f"seed {row['seed']}: {row['reports']} reports, link {links}; "
            f"arrived {'all' if row['all_arrived'] else ', '.join(row['arrived']) or 'none'}"
        )
        for o in row["outages"]:
            until = "end" if o["until_s"] is None else f"{o['until_s']:.0f} s"
            print(f"  outage {o['robot']} {o['from_s']:.0f} s - {until}: {o['cause']} (said: {o['said']})")
        if not row["all_arrived"]:
            for u, (status, reason) in row["reasons"].items():
                print(f"  {u}: {status} {reason}")
    verdict = "met" if fig["link_pct_min"] >= fig["target_pct"] else "MISSED"
    print(
        f"link min {fig['link_pct_min']:.1f} %, mean {fig['link_pct_mean']:.1f} % (target >= {fig['target_pct']:.0f} %: "
        f"{verdict}); {fig['outages']} outages; all arrived in {fig['all_arrived']} of {fig['seeds']}"
    )
