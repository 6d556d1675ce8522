"""Real vehicles: guidance at any report rate, speed, stop and GPS noise, in process, against the preview.

Each vehicle is written from the wire contract alone (``docs/wire.md``), not
from ``pfp fleet``'s simulator: it reports its (noisy) fix at its own rate
with its own ``t`` and ``speed_mps`` (0 while stopped), never gives a
``step``, and between two reports drives at its own speed along the newest
direction, no further than its ``reach_m``, nor past the goal.  The planner
is the service's own ``World`` (deliberation deferred, as ``pfp serve`` runs
it; each job is run at once, as an idle worker would, and its answer applied
with the next report).

Two families, each vehicle alone in its world so that one cannot disturb
another's figures:

* ``open``: no threat and no zone, a straight route of ``ROUTE_S`` seconds of
  the vehicle's own driving (5 km at 15 m/s).  Target: no answer ``escaping``
  or ``trapped``, and arrival within 1.2x the straight-line time plus its stops.
* ``threats``: three threats that bend a 600 m route with no trap (the same
  geometry for every vehicle).  Target: every vehicle arrives, none is told
  ``trapped``; the driven track's exposure (of its true positions) is at most
  1.2x that of the preview it was shown at its start; the exposures of all
  vehicles agree within 1.2x.

``--check`` exits 1 when a target is missed.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import random
import time
from dataclasses import dataclass, field

ROUTE_S = 333.0  # the open family's route: this many seconds of the vehicle's own driving
RATES_HZ = (0.5, 2.0, 20.0)
SPEEDS_MPS = (1.0, 4.0, 15.0)
STOPS = ((30.0, 10.0), (90.0, 30.0))  # (at_s, for_s)
GPS_SIGMA_M = 3.0
TARGET_TIME = 1.2
TARGET_EXPOSURE = 1.2
THREATS = (  # three threats that bend a 600 m route east, with no trap: (x, y, facing_deg, sigma_r, sigma_l)
    (200.0, 20.0, 270.0, 40.0, 30.0),
    (330.0, -25.0, 270.0, 40.0, 30.0),
    (450.0, 30.0, 270.0, 35.0, 30.0),
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="one stop, rates 2 and 20 Hz, speeds 4 and 15 m/s")
    p.add_argument("--seed", type=int, default=0, help="seeds the GPS noise")
    p.add_argument("--check", action="store_true", help="exit 1 when a target is missed")


@dataclass
class Vehicle:
    """A vehicle written from the wire contract: its true position, and what it was last told."""

    start: tuple[float, float]
    speed_mps: float
    rate_hz: float
    stops: tuple[tuple[float, float], ...]
    sigma_m: float
    rng: random.Random
    x: float = 0.0
    y: float = 0.0
    vector: tuple[float, float] = (0.0, 0.0)
    left_m: float = 0.0  # how much further the newest direction is good for
    to_goal: float = math.inf
    track: list[tuple[float, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.x, self.y = self.start
        self.track.append(self.start)

    def stopped(self, t: float) -> bool:
        return any(at <= t < at + dur for at, dur in self.stops)

    def fix(self) -> tuple[float, float]:
        return (self.x + self.rng.gauss(0.0, self.sigma_m), self.y + self.rng.gauss(0.0, self.sigma_m))

    def told(
        self, status: str, vector: tuple[float, float], reach: float | None, to_goal: float | None
    ) -> None:
        moving = status in ("en_route", "escaping")
        self.vector = vector if moving else (0.0, 0.0)
        self.left_m = (math.inf if reach is None else reach) if moving else 0.0
        self.to_goal = math.inf if to_goal is None else to_goal

    def drive(self, t0: float, t1: float) -> None:
        """Drive from ``t0`` to ``t1`` (in slices, so that a stop starting meanwhile is kept)."""
        t = t0
        while t < t1 - 1e-12:
            dt = min(0.05, t1 - t)
            if not self.stopped(t):
                d = min(self.speed_mps * dt, self.left_m, self.to_goal)
                if d > 0.0:
                    self.x += d * self.vector[0]
                    self.y += d * self.vector[1]
                    self.left_m -= d
                    self.to_goal -= d
            t += dt
        self.track.append((self.x, self.y))


@dataclass
class Outcome:
    family: str
    rate_hz: float
    speed_mps: float
    arrived_s: float | None
    nominal_s: float
    reports: int
    escaping: int
    trapped: int
    exposure: float
    preview_exposure: float
    length: float


def _drive_one(
    family: str, rate: float, speed: float, stops: tuple[tuple[float, float], ...], seed: int
) -> Outcome:
    from pfp_service.core import PlannerParams
    from pfp_service.core.metrics import exposure
    from pfp_service.wire import Goal, ThreatUpdate, UnitState
    from pfp_service.world.events import GoalSet, StateReported, ThreatPut
    from pfp_service.world.preview import preview
    from pfp_service.world.world import World, WorldSettings

    w = World(WorldSettings(deliberation="deferred", planner=PlannerParams()))
    if family == "open":
        start, goal, threats = (0.0, 0.0), (speed * ROUTE_S * 0.6, speed * ROUTE_S * 0.8), []
    else:
        start, goal = (0.0, 0.0), (600.0, 0.0)
        threats = [
            ThreatPut(f"t{i}", ThreatUpdate(position=(x, y), facing_deg=f, sigma_range=sr, sigma_lateral=sl))
            for i, (x, y, f, sr, sl) in enumerate(THREATS)
        ]
    rng = random.Random(seed * 1_000_003 + int(rate * 100) * 1009 + int(speed * 100))
    v = Vehicle(start, speed, rate, stops, GPS_SIGMA_M, rng)
    period = 1.0 / rate
    t, seq = 0.0, 0
    pending: list = []
    out = w.apply(
        [*threats, StateReported("v", UnitState(position=start, t=0.0)), GoalSet("v", Goal(position=goal))],
        0.0,
    )
    pending = [job.run(0.0) for job in out.jobs]
    out = w.apply(pending, 0.0)  # its route lands before it moves, as with an idle worker
    view = w.view("v")
    shown = preview(view, None, time.monotonic, 60.0, 1_000_000)
    fld = w.field if threats else None
    escaping = trapped = reports = 0
    arrived = None
    limit = 4.0 * (math.dist(start, goal) / speed + sum(d for _, d in stops)) + 60.0
    pending = []
    while t < limit:
        seq += 1
        stopped = v.stopped(t)
        state = UnitState(position=v.fix(), t=t, seq=seq, speed_mps=0.0 if stopped else speed)
        out = w.apply([*pending, StateReported("v", state)], t)
        pending = [job.run(t) for job in out.jobs]
        mine = [d for d in out.directions if d.unit == "v"]
        reports += 1
        if mine:
            d = mine[-1]
            escaping += d.status.value == "escaping"
            trapped += d.status.value == "trapped"
            if d.status.value == "arrived":
                arrived = t
                break
            v.told(d.status.value, d.vector, d.reach_m, d.distance_to_goal)
        v.drive(t, t + period)
        t += period
    import numpy as np

    path = np.array(v.track)
    driven = exposure(path, fld) if fld is not None else 0.0
    length = float(np.hypot(*np.diff(path, axis=0).T).sum())
    end = arrived if arrived is not None else t
    nominal = math.dist(start, goal) / speed + sum(min(d, end - at) for at, d in stops if at < end)
    return Outcome(
        family, rate, speed, arrived, nominal, reports, escaping, trapped, driven, shown.exposure, length
    )


def run(args: argparse.Namespace) -> int:
    rates = (2.0, 20.0) if args.quick else RATES_HZ
    speeds = (4.0, 15.0) if args.quick else SPEEDS_MPS
    stops = STOPS[:1] if args.quick else STOPS
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"# pfp bench vehicles (load average {load}); GPS sigma {GPS_SIGMA_M:g} m, stops {list(stops)}")
    rows: list[Outcome] = []
    for family, rate, speed in itertools.product(("open", "threats"), rates, speeds):
        t0 = time.perf_counter()
        o = _drive_one(family, rate, speed, stops, args.seed)
        rows.append(o)
        arrived = f"{o.arrived_s:8.1f}" if o.arrived_s is not None else "     not"
        ratio = (o.arrived_s / o.nominal_s) if o.arrived_s is not None else math.inf
        ex = f"{o.exposure:7.3f} / {o.preview_exposure:7.3f}" if family == "threats" else "      -"
        print(
            f"{family:8} {rate:5.1f} Hz {speed:5.1f} m/s  arrived {arrived} s (x{ratio:4.2f} of straight+stops)  "
            f"reports {o.reports:6d}  escaping {o.escaping:4d}  trapped {o.trapped:4d}  exposure driven/preview {ex}"
            f"  ({time.perf_counter() - t0:.1f} s)"
        )
    misses = []
    for o in rows:
        name = f"{o.family} {o.rate_hz:g} Hz {o.speed_mps:g} m/s"
        if o.arrived_s is None:
            misses.append(f"{name}: did not arrive")
        if o.trapped:
            misses.append(f"{name}: answered trapped {o.trapped} times")
        if o.family == "open":
            if o.escaping:
                misses.append(f"{name}: answered escaping {o.escaping} times in open ground")
            if o.arrived_s is not None and o.arrived_s > TARGET_TIME * o.nominal_s:
                misses.append(f"{name}: {o.arrived_s:.0f} s > {TARGET_TIME} x {o.nominal_s:.0f} s")
        elif o.preview_exposure > 0 and o.exposure > TARGET_EXPOSURE * o.preview_exposure:
            misses.append(
                f"{name}: exposure {o.exposure:.3f} > {TARGET_EXPOSURE} x preview {o.preview_exposure:.3f}"
            )
    driven = [o.exposure for o in rows if o.family == "threats" and o.arrived_s is not None]
    if driven:
        spread = max(driven) / max(min(driven), 1e-12)
        print(f"threats: driven exposures {min(driven):.3f}-{max(driven):.3f}, spread x{spread:.3f}")
        if spread > TARGET_EXPOSURE:
            misses.append(f"driven exposures spread x{spread:.2f} > {TARGET_EXPOSURE}")
    for m in misses:
        print(f"MISSED: {m}")
    if not misses:
        print("every target met")
    return 1 if args.check and misses else 0
