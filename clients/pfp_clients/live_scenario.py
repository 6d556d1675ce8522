"""A scenario file (the one ``pfp plan`` takes) played into a live mission: one document, plan or live.

``pfp inject SCENARIO.yaml`` sees a file with ``start`` and ``goal`` (and no
``timeline``) as a scenario.  It becomes

* an injection script (``pfp_clients.script.Script``): every threat an
  ``add_threat`` (a threat that appears at plan step ``k`` is put at
  ``k`` ticks of the simulated unit, ``at_s = k / rate_hz``), every keep-out
  zone an ``add_zone``, then the unit's goal with the step, tolerance and
  delta the plan resolves, and the expectations that the unit arrives and
  never enters a zone;
* one simulated unit at ``start`` (the fleet's sim), moving one plan step per
  tick, so the live stream walks the same steps the plan does, its states
  naming the ``unit:`` block's mobility class (and its slope limit, height
  and speed, where given);
* the plan itself, computed here with the same engine, to judge the live
  track against: every live point within ``tolerance`` (the goal's arrival
  tolerance) of the planned path, and every planned point of the live track.

With ``--no-sim`` only the script is played: a real unit at ``start`` drives.
The live planner's ``--intensity``/``--escape`` must be the scenario's for the
paths to agree (a goal carries step, tolerance and delta, not those).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from pfp_clients.script import AddThreat, AddZone, Expect, Script, SetGoal, Step
from pfp_service.core.mobility import CLASS_LIMITS, planned_limit
from pfp_service.errors import InputError
from pfp_service.files import read_text
from pfp_service.scenario import Scenario, load_scenario
from pfp_service.team import MobilitySpec, Team, UnitSpec
from pfp_service.yamlio import load

__all__ = [
    "LiveScenario",
    "deviation_m",
    "is_scenario_file",
    "live_scenario",
]

ARRIVAL_MARGIN = 3.0  # the unit's arrival deadline: this many times the plan's own steps, in ticks


@dataclass(frozen=True)
class LiveScenario:
    """What a scenario becomes live: the script, the simulated unit, and the plan to compare with."""

    scenario: Scenario
    script: Script
    team: Team
    unit: str
    rate_hz: float
    plan_path: np.ndarray  # (n, 2) metres in the scenario's frame
    plan_status: str
    tolerance_m: float


def is_scenario_file(path: str | Path) -> bool:
    """Whether ``path`` holds a scenario (``start`` and ``goal``, no ``timeline``), not a script.

    A file that does not parse is not judged here: the script loader names its line.
    """
    p = Path(path)
    try:
        doc = load(read_text(p))
    except Exception:  # any parse problem: the loader that owns the format names its line
        return False
    return isinstance(doc, dict) and "start" in doc and "goal" in doc and "timeline" not in doc


def _threat_step(i: int, t: Any, tid: str, dt_s: float) -> AddThreat:
    if t.omega is not None:
        raise InputError(
            f"threats[{i}].omega",
            "the raw form (omega, alpha) cannot go live: the wire takes facing_deg, sigma_range and sigma_lateral",
        )
    return AddThreat(
        threat=tid,
        position=t.position,
        shape=t.shape,
        params=t.params,
        facing_deg=((t.facing_deg + 360.0) % 720.0) - 360.0,  # the wire's -360..360
        sigma_range=t.sigma_range,
        sigma_lateral=t.sigma_lateral,
        skew=t.skew,
        weight=t.weight,
        at_s=t.appear_step * dt_s if t.appear_step else None,
    )


def _zone_steps(sc: Scenario) -> list[AddZone]:
    """An ``add_zone`` entry for each of the scenario's keep-out zones (already in metres)."""
    return [
        AddZone(zone=z.id or f"z{i + 1}", kind=z.kind, polygon=z.polygon, circle=z.circle, ttl_s=z.ttl_s)
        for i, z in enumerate(sc.zones)
    ]


def live_scenario(path: str | Path, unit: str = "u1", rate_hz: float = 5.0) -> LiveScenario:
    """Read a scenario and build its live form.

    Raises:
        InputError: the scenario is invalid (naming the file and line), or cannot go live.
    """
    from pfp_service.core import plan
    from pfp_service.core.params import resolve
    from pfp_service.wire import keys

    p = Path(path)
    keys.check_chunk(unit, "--unit")
    sc = load_scenario(p)
    dt_s = 1.0 / rate_hz
    params = sc.planner.to_params()
    schedule = sc.schedule()
    r = resolve(params, sc.start, sc.goal, [s.threat for s in schedule])
    steps: list[Step] = []
    try:
        for i, t in enumerate(sc.threats):
            steps.append(_threat_step(i, t, t.id or f"t{i + 1}", dt_s))
        steps.extend(_zone_steps(sc))
    except InputError as err:
        raise InputError(f"{p.name}, {err.path}", err.reason) from None
    steps.append(SetGoal(unit=unit, position=sc.goal, step=r.step, tolerance=r.tolerance, delta=r.delta))
    zones = _zone_steps(sc)
    result = plan(sc.start, sc.goal, schedule, params, sc.bounds_tuple(), zones=sc.zone_set())
    path_xy = np.asarray(result.path, dtype=float).reshape(-1, 2)
    ticks = max(len(path_xy), 10)
    duration = ARRIVAL_MARGIN * ticks * dt_s + 10.0
    script = Script(
        name=sc.name,
        origin=sc.origin,
        duration_s=duration,
        timeline=steps,
        expect=[
            Expect(unit=unit, arrives_within_s=duration),
            *(Expect(unit=unit, never_enters=z.zone) for z in zones),
        ],
    )
    slope = sc.unit.max_slope_deg
    if slope is not None and planned_limit(slope) is None:
        raise InputError(
            f"{p.name}, unit.max_slope_deg",
            f"{slope:g} is below {CLASS_LIMITS[0]}, the gentlest slope limit a live planner plans",
        )
    u = sc.unit
    try:  # the wire's bounds on the overrides, narrower than a plan's
        mobility = msgspec.convert(
            {"class": u.kind, "max_slope_deg": slope, "height_m": u.height_m, "speed_mps": u.speed_mps},
            MobilitySpec,
        )
    except msgspec.ValidationError as exc:
        raise InputError(f"{p.name}, unit", f"{exc} (a live planner's bounds)") from exc
    team = Team(
        name=sc.name,
        origin=sc.origin,
        units=[
            UnitSpec(id=unit, start=sc.start, goal=sc.goal, speed_mps=r.step * rate_hz, mobility=mobility)
        ],
    )
    return LiveScenario(sc, script, team, unit, rate_hz, path_xy, str(result.status), r.tolerance)


def _to_polyline(points: np.ndarray, line: np.ndarray) -> float:
    """The largest distance from any of ``points`` to the polyline ``line``."""
    if len(line) == 1:
        return float(np.max(np.hypot(*(points - line[0]).T)))
    a, b = line[:-1], line[1:]
    ab = b - a
    den = np.maximum((ab * ab).sum(1), 1e-300)
    worst = 0.0
    for chunk in np.array_split(points, max(1, len(points) // 256)):
        ap = chunk[:, None, :] - a[None, :, :]
        t = np.clip((ap * ab[None]).sum(2) / den[None], 0.0, 1.0)
        near = a[None] + t[..., None] * ab[None]
        d = np.hypot(*(chunk[:, None, :] - near).transpose(2, 0, 1)).min(1)
        worst = max(worst, float(d.max()))
    return worst


def deviation_m(live: np.ndarray, planned: np.ndarray) -> float:
    """The Hausdorff distance between two polylines' vertices and the other polyline, in metres."""
    live = np.asarray(live, dtype=float).reshape(-1, 2)
    planned = np.asarray(planned, dtype=float).reshape(-1, 2)
    if len(live) == 0 or len(planned) == 0:
        return math.inf
    return max(_to_polyline(live, planned), _to_polyline(planned, live))


def play(
    conf: Any,
    ls: LiveScenario,
    mission: str,
    speed_up: float,
    say: Any = print,
    stop: Any = None,
    sim: bool = True,
) -> int:
    """Play ``ls`` on a live mission: the script, and (``sim``) its unit; 0 iff it arrived as planned.

    The script and the simulated unit share one clock, the fleet's (as ``pfp demo`` does), and the
    unit starts once the planner has taken the threats and the goal.

    Raises:
        ZenohError: the session cannot be opened.
    """
    import contextlib
    import threading

    from pfp_clients.common import open_session_waiting
    from pfp_clients.fleet import FleetOptions, run_fleet
    from pfp_clients.frames import planner_origin, reframe
    from pfp_clients.inject import report_lines, run_inject

    stop = stop or threading.Event()
    lock = threading.Lock()

    def said(text: str) -> None:  # two threads report: one line at a time
        with lock:
            say(text)

    first = open_session_waiting(conf, said, stop)
    if first is None:
        return 1
    results: dict[str, Any] = {}
    errors: list[BaseException] = []
    clock = [0.0]
    ready = threading.Event()
    with contextlib.ExitStack() as stack:
        sessions = [stack.enter_context(first)]
        if sim:
            from pfp_clients.common import open_session

            sessions.append(stack.enter_context(open_session(conf)))
        said(
            f"scenario {ls.scenario.name}: {len(ls.scenario.threats)} threats, unit {ls.unit} from "
            f"({ls.scenario.start[0]:g}, {ls.scenario.start[1]:g}) to ({ls.scenario.goal[0]:g}, "
            f"{ls.scenario.goal[1]:g}); the plan {ls.plan_status} in {len(ls.plan_path) - 1} steps"
        )

        def inject() -> None:
            try:
                results["inject"] = run_inject(
                    sessions[0],
                    ls.script,
                    mission,
                    speed_up,
                    say=said,
                    stop=stop,
                    ready=ready,
                    mission_clock=(lambda: clock[0]) if sim else None,
                    ready_after_acks=True,
                )
            except BaseException as exc:  # reported below
                errors.append(exc)
                ready.set()

        threads = [threading.Thread(target=inject, name="scenario-inject", daemon=True)]
        threads[0].start()
        if sim:
            while not ready.wait(0.05) and not stop.is_set():
                pass  # the threats and the goal are in force before the unit reports
            fopts = FleetOptions(
                mission=mission,
                rate_hz=ls.rate_hz,
                speed_up=speed_up,
                duration_s=ls.script.duration_s,
                until_arrived=True,
                set_goals=False,
            )

            def on_tick(t_s: float, _units: Any) -> None:
                clock[0] = t_s

            if not errors:
                results["fleet"] = run_fleet(sessions[1], ls.team, fopts, stop, say=said, on_tick=on_tick)
            threads[0].join(timeout=3.0)
            stop.set()
        threads[0].join()
        planner = planner_origin(sessions[0], mission)[1] if sim else None
    if errors:
        raise errors[0]
    rep = results["inject"]
    for line in report_lines(rep):
        said(line)
    ok = rep.ok
    if sim and "fleet" in results:
        track = np.array([(p.x, p.y) for p in results["fleet"].units[0].track], dtype=float)
        back = None
        if planner is not None and ls.scenario.origin is not None:
            back = reframe(planner, ls.scenario.origin, mission, "planner")
        if back is not None and len(track):
            track = np.array([back((float(x), float(y))) for x, y in track])
        dev = deviation_m(track, ls.plan_path)
        held = dev <= ls.tolerance_m
        said(
            f"  {'PASS' if held else 'FAIL'}  live track of {ls.unit} follows the plan within "
            f"{ls.tolerance_m:.3g} m: largest deviation {dev:.3g} m over {len(track)} live and "
            f"{len(ls.plan_path)} planned points"
        )
        ok = ok and held
    return 0 if ok else 1
