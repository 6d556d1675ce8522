"""``pfp demo``: the whole system in one command -- planner, fleet and a contingency script.

It opens an embedded router on a free loopback port with an in-process
``PlannerNode``, plays ``examples/demo-inject.yaml`` on one client session,
starts the team of ``examples/demo-team.yaml`` on another once the known
threats are in, prints progress once a second, and ends when every unit has
arrived (or the script's duration passed).  Then it prints a summary table
(unit, status, time, path length, exposure, minimum clearance; exposure and
clearance measured on the fleet's own track under the threats in force when
each segment was walked) and writes a PNG of the threat contours and tracks,
with a star where the contingency struck.

One clock: the fleet's simulated mission time.  The script's triggers and
deadlines, every log line, the summary and the plot read it, so a busy
machine slows the demo down but cannot make a unit "late": when the planner
answers slowly the fleet waits (lockstep), and mission time waits with it.
"""

from __future__ import annotations

import contextlib
import math
import socket
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from pfp_clients.expectations import InjectReport
from pfp_clients.fleet import FleetOptions, FleetResult, run_fleet
from pfp_clients.inject import report_lines, run_inject
from pfp_clients.script import AddTeam, AddThreat, SetGoal, load_script
from pfp_clients.sim import SimUnit
from pfp_service.core.metrics import Epoch, measure
from pfp_service.core.threat import ThreatField
from pfp_service.errors import map_zenoh_errors
from pfp_service.team import load_team
from pfp_service.world.team_goal import places

__all__ = [
    "DEMO_SCRIPT",
    "DEMO_TEAM",
    "DEMO_TEAMS_SCRIPT",
    "DEMO_TEAMS_TEAM",
    "DEMO_TERRAIN_SCRIPT",
    "DEMO_TERRAIN_TEAM",
    "DemoOptions",
    "run_demo",
]

# a source checkout keeps examples/ beside clients/; an installed copy (the docker image) finds it in the cwd
_EXAMPLES = next(
    (p for p in (Path(__file__).resolve().parents[2] / "examples", Path.cwd() / "examples") if p.is_dir()),
    Path("examples"),
)
DEMO_TEAM = _EXAMPLES / "demo-team.yaml"
DEMO_SCRIPT = _EXAMPLES / "demo-inject.yaml"
DEMO_TERRAIN_TEAM = _EXAMPLES / "demo-terrain-team.yaml"
DEMO_TERRAIN_SCRIPT = _EXAMPLES / "demo-terrain-inject.yaml"
DEMO_TEAMS_TEAM = _EXAMPLES / "demo-teams-team.yaml"  # the teaming variant: its units, with no goals
DEMO_TEAMS_SCRIPT = _EXAMPLES / "demo-teams-inject.yaml"  # ... its teams, each with one goal
TERRAIN_UNIT = "tracked"  # the class the terrain variant plans for: its team drives tracked vehicles
MISSION = "demo"
INJECT_GRACE_S = 3.0  # wall seconds the script may take, after the fleet stopped, to see the last answers


@dataclass(frozen=True)
class DemoOptions:
    """What ``pfp demo`` can be told."""

    out: Path = Path("demo.png")
    speed_up: float = 5.0
    rate_hz: float = 5.0
    team: Path = DEMO_TEAM
    script: Path = DEMO_SCRIPT
    progress_every_s: float = 1.0  # wall seconds between progress lines
    map_port: int | None = None  # serve the live map on 127.0.0.1 at this port (0: any free one)
    terrain: Path | None = None  # plan over this DEM (the terrain variant), for TERRAIN_UNIT vehicles


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _progress(t_s: float, units: Sequence[SimUnit]) -> str:
    parts = []
    for u in units:
        d = u.direction
        togo = f"{d.distance_to_goal:5.1f}m" if d is not None and d.distance_to_goal is not None else "   -  "
        parts.append(f"{u.id} {u.status[:8]:<8} {togo}")
    return f"t={t_s:6.1f}s | " + " | ".join(parts)


def summary_rows(
    fleet: FleetResult, rep: InjectReport, intensity: str, sight: Any = None
) -> list[tuple[str, ...]]:
    """Per unit: status, arrival time, path length, exposure and minimum clearance.

    With ``sight`` (the planner's terrain), the exposure is the threats' as line of sight masks it.
    """
    head = "exposure in view" if sight is not None else "exposure"
    rows: list[tuple[str, ...]] = [("unit", "kind", "status", "time s", "path m", head, "min clear m")]
    for u in fleet.units:
        path = np.array([(p.x, p.y) for p in u.track], dtype=float).reshape(-1, 2)
        # one mission clock: segments are judged under the threats the script had put by then
        times = [p.t_s for p in u.track]
        epochs = [ep for ep, _ in rep.watch.epochs(times, intensity)]
        if sight is not None:  # the same threats, each seeing only over the ground
            epochs = [
                Epoch(e.first, e.last, ThreatField(e.field.threats, e.field.intensity, sight=sight))
                for e in epochs
            ]
        m = measure(path, epochs) if len(path) > 1 else None
        arrived = f"{u.arrived_at_s:.1f}" if u.arrived_at_s is not None else "-"
        if m is None:
            rows.append((u.id, u.spec.kind.value, u.status, arrived, "0.0", "-", "-"))
            continue
        clear = "inf" if math.isinf(m.min_clearance) else f"{m.min_clearance:.2f}"
        rows.append(
            (u.id, u.spec.kind.value, u.status, arrived, f"{m.length:.1f}", f"{m.exposure:.3f}", clear)
        )
    return rows


def _table(rows: list[tuple[str, ...]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def _plot(fleet: FleetResult, rep: InjectReport, intensity: str, out: Path) -> None:
    from pfp_service.render import plot_tracks

    latest: dict[str, Any] = {}
    first: dict[str, Any] = {}
    for v in rep.watch.versions:
        latest[v.threat_id] = v.threat()
        first.setdefault(v.threat_id, v.threat())
    moved = [(first[t], latest[t]) for t in latest if first[t].xi != latest[t].xi]
    tracks: dict[str, Sequence[Sequence[float]]] = {u.id: [(p.x, p.y) for p in u.track] for u in fleet.units}
    goals: dict[str, Sequence[float]] = {u.id: u.spec.goal for u in fleet.units if u.spec.goal is not None}
    old_goals: dict[str, Sequence[float]] = {}
    for f in rep.fired:  # goals the script gave (a team's: each member's place, as the planner gives it)
        if isinstance(f.step, AddTeam):
            goals.update({u: g.position for u, g in places(f.step.update()).items()})
        if isinstance(f.step, SetGoal):
            if f.step.unit in goals and tuple(goals[f.step.unit]) != tuple(f.step.position):
                old_goals.setdefault(f.step.unit, goals[f.step.unit])
            goals[f.step.unit] = f.step.position
    marks = []
    for f in rep.fired:
        if f.where is not None and f.step.when is not None:
            what = f.step.threat if isinstance(f.step, AddThreat) else f.step.describe()
            marks.append(
                (f.where[0], f.where[1], f"{what} struck at t={f.t_s:.0f}s ({f.step.when.unit} here)")
            )
    held = sum(v.held for v in rep.verdicts)
    title = (
        f"pfp demo: {sum(u.arrived for u in fleet.units)}/{len(fleet.units)} arrived, "
        f"{held}/{len(rep.verdicts)} expectations held"
        + ("" if rep.ok and fleet.all_arrived else " - FAILED")
    )
    plot_tracks(
        list(latest.values()),
        intensity,
        tracks,
        goals,
        out,
        title=title,
        marks=marks,
        old_threats=moved,
        old_goals=old_goals,
    )


def run_demo(opts: DemoOptions, say_line: Any = print, stop: threading.Event | None = None) -> int:
    """Run the demo; 0 iff every unit arrived and every expectation held.

    ``stop`` (SIGTERM, SIGINT) ends it early: everything it opened is closed, no
    summary or plot is made, and it returns 1.
    """
    import zenoh

    lock = threading.Lock()

    def say(text: str) -> None:  # three threads report: one line at a time
        with lock:
            say_line(text)

    from pfp_clients.common import client_config, open_session
    from pfp_service.node.config import ServeConfig, zenoh_config
    from pfp_service.node.log import setup_logging
    from pfp_service.node.node import PlannerNode

    wall0 = time.monotonic()
    team = load_team(opts.team)
    script = load_script(opts.script)
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    cfg = ServeConfig(mission=MISSION, listen=[endpoint], log_level="error", escape="auto")
    if opts.terrain is not None:  # loaded once, its centre the origin, as pfp serve --terrain does
        from pfp_service.node.terrain import placed

        cfg = placed(msgspec.structs.replace(cfg, terrain=str(opts.terrain), terrain_unit=TERRAIN_UNIT))
    setup_logging(cfg.log_format, cfg.log_level)
    say(f"planner: embedded router on {endpoint}, mission {MISSION!r}; speed-up x{opts.speed_up:g}")
    if opts.terrain is not None:
        say(
            f"terrain: {opts.terrain.name}, planned for {TERRAIN_UNIT} vehicles; origin its centre {cfg.origin}"
        )
    results: dict[str, Any] = {}
    errors: list[BaseException] = []
    latest: list[tuple[float, Sequence[SimUnit]]] = []
    mission_s = [0.0]  # the fleet's simulated time: the demo's one clock

    def on_tick(t_s: float, units: Sequence[SimUnit]) -> None:
        mission_s[0] = t_s
        latest.append((t_s, units))

    stop = stop or threading.Event()
    ready = threading.Event()
    with map_zenoh_errors("demo router"):
        router = zenoh.open(zenoh_config(cfg))
    with router, contextlib.ExitStack() as stack:  # closed in reverse: clients, node, then the router
        node = PlannerNode(router, cfg)
        node.start()
        stack.callback(node.stop)
        sessions = [stack.enter_context(open_session(client_config([endpoint]))) for _ in range(2)]
        if opts.map_port is not None:  # the operator's live map of this very demo
            from pfp_clients.map.embed import MapThread
            from pfp_clients.map.server import MapOptions

            url = stack.enter_context(
                MapThread(client_config([endpoint]), MapOptions(mission=MISSION, port=opts.map_port))
            )
            say(f"map: {url}")
        stack.callback(stop.set)

        def inject() -> None:
            try:
                results["inject"] = run_inject(
                    sessions[0],
                    script,
                    MISSION,
                    opts.speed_up,
                    say=say,
                    stop=stop,
                    ready=ready,
                    mission_clock=lambda: mission_s[0],
                )
            except BaseException as exc:  # reported by the main thread
                errors.append(exc)
                ready.set()

        def fleet() -> None:
            fopts = FleetOptions(
                mission=MISSION,
                rate_hz=opts.rate_hz,
                speed_up=opts.speed_up,
                duration_s=script.duration_s,
                until_arrived=True,
            )
            try:
                results["fleet"] = run_fleet(sessions[1], team, fopts, stop, say=say, on_tick=on_tick)
            except BaseException as exc:
                errors.append(exc)

        threads = [threading.Thread(target=inject, name="demo-inject", daemon=True)]
        threads[0].start()
        ready_by = time.monotonic() + 10.0  # the known threats are in before any goal is set
        while not ready.wait(0.05) and not stop.is_set() and time.monotonic() < ready_by:
            pass
        threads.append(threading.Thread(target=fleet, name="demo-fleet", daemon=True))
        threads[1].start()
        next_line = time.monotonic() + opts.progress_every_s
        while threads[1].is_alive():
            threads[1].join(timeout=0.05)
            if time.monotonic() >= next_line and latest:
                say(_progress(*latest[-1]))
                next_line += opts.progress_every_s
        stopped_early = stop.is_set()  # a signal: the fleet stopped short of its end
        # mission time stops with the fleet: the script only has the last answers left to see
        threads[0].join(timeout=0 if stopped_early else INJECT_GRACE_S)
        stop.set()
        threads[0].join(timeout=5.0)
    if errors:
        raise errors[0]
    if stopped_early:
        say(f"demo stopped after {time.monotonic() - wall0:.1f} s wall; no summary, no plot")
        return 1
    fleet_result: FleetResult = results["fleet"]
    rep: InjectReport = results["inject"]
    say("")
    sight = cfg.world_settings().terrain if opts.terrain is not None else None
    for line in _table(summary_rows(fleet_result, rep, cfg.intensity, sight)):
        say(line)
    say("expectations:")
    for line in report_lines(rep):
        say(line)
    _plot(fleet_result, rep, cfg.intensity, opts.out)
    say(f"wrote {opts.out}; demo took {time.monotonic() - wall0:.1f} s wall")
    return 0 if rep.ok and fleet_result.all_arrived else 1
