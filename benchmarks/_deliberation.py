"""Deliberation in process: the goal storm's look-aheads as a worker runs them, and the contingency wave's ``apply``.

The same field and fleet as ``pfp bench service`` (``bench._layout``: units
on the west edge, goals on the east edge, threats facing west between them),
driven through ``World.apply`` with deliberation deferred, so nothing here
starts a process or opens a session:

* **storm**: every unit reports, then every goal is set at once; each job the
  world asks for is run as a deliberation worker runs it (its stepper through
  a pickle, the field shared, as the worker's cache shares it), and its CPU
  time taken.  ``one_worker_s`` is their sum: when the last look-ahead would
  land with one worker and nothing else on its core.  Results go back to the
  world, as the node feeds them.
* **wave**: on that settled world (a copy per repeat, collected before it),
  one threat put just ahead of the fleet's centre, as the fan-out phase puts
  it; the figure is ``World.apply`` for that one input, which returns the new
  directions (the node publishes them before it sends any job,
  ``Job.detach``), then the collection it held off (``gcpause``), timed at
  the first allocation after it, and the ticks that follow until the world
  has no wave pending (their points and jobs, a bounded share a tick): the median
  and the largest.
"""

from __future__ import annotations

import copy
import gc
import pickle
import statistics
import time
import types
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from pfp_service.world.world import Outputs

__all__ = ["STORM_UNITS", "TARGET_LOOKAHEAD_MS", "TARGET_WAVE_MS", "print_storm_and_wave", "storm_and_wave"]

STORM_UNITS = 1000
STORM_THREATS = 100
TARGET_LOOKAHEAD_MS = 4.0  # issue 23: the storm's look-aheads, mean worker CPU
TARGET_WAVE_MS = 10.0  # issue 23: one threat ahead of 1,000 units, World.apply in process


def storm_and_wave(units: int = STORM_UNITS, repeat: int = 5, seed: int = 2023) -> dict[str, Any]:
    """The storm's look-aheads and then the wave, on one world (see the module's docstring)."""
    from benchmarks._layout import layout
    from pfp_service.core.routes import ROUTES
    from pfp_service.node import gcpause
    from pfp_service.wire import Goal, ThreatUpdate, UnitState
    from pfp_service.world.world import (
        GoalSet,
        Input,
        StateReported,
        ThreatPut,
        Tick,
        World,
        WorldSettings,
    )

    lay = layout(units, STORM_THREATS, seed)
    w = World(WorldSettings(deliberation="deferred", unit_forget_s=None, unit_stale_s=1e9))
    w.apply([ThreatPut(t, u) for t, u in lay["threats"]], 0.0)
    ids = [f"u{i}" for i in range(units)]
    w.apply([StateReported(u, UnitState(position=lay["starts"][i], seq=0)) for i, u in enumerate(ids)], 1.0)
    t0 = time.perf_counter()
    out = w.apply([GoalSet(u, Goal(position=lay["goals"][i], step=1.0)) for i, u in enumerate(ids)], 2.0)
    goals_ms = (time.perf_counter() - t0) * 1e3
    ROUTES.clear()  # a worker's cache starts empty
    cpu, kinds = [], {"foreseen": 0, "cheaper": 0, "none": 0}
    done: list[Input] = []
    for job in out.jobs:
        job.stepper = pickle.loads(pickle.dumps(job.detach()))  # what the worker gets
        c0 = time.process_time()
        result = job.run(None)
        cpu.append(time.process_time() - c0)
        run = result.stepper._run if result.stepper is not None else None
        kinds["none" if run is None else "foreseen" if "foreseen" in run.name else "cheaper"] += 1
        done.append(result)
    ms = np.array(cpu) * 1e3
    w.apply(done, 3.0)
    w.apply([StateReported(u, UnitState(position=lay["starts"][i], seq=1)) for i, u in enumerate(ids)], 4.0)
    pts = np.asarray(lay["starts"][:units])
    at = (float(np.median(pts[:, 0])) + 60.0, float(np.median(pts[:, 1])))
    threat = ThreatUpdate(position=at, facing_deg=270.0, sigma_range=40.0, sigma_lateral=28.0, skew=2.0)
    waves, afters, thens, then_max, ticks, copies, directions, jobs = [], [], [], [], 0, [], 0, 0
    for _ in range(repeat):
        world = copy.deepcopy(w)
        gc.collect()  # the copy's own collection: a serving planner copies no world
        t0 = time.perf_counter()
        with gcpause.paused():  # as the node's loop holds the collector off round each apply
            wave = world.apply([ThreatPut("contingency", threat)], 5.0)
        t1 = time.perf_counter()
        types.SimpleNamespace()  # the first allocation after: the collection apply held off runs here
        afters.append((time.perf_counter() - t1) * 1e3)
        waves.append((t1 - t0) * 1e3)
        follow: list[Outputs] = []
        now = 5.0
        while (
            world.wave_pending() or not follow
        ):  # a big wave's points and jobs follow, a bounded share a tick
            now += 0.002
            t0 = time.perf_counter()
            with gcpause.paused():
                follow.append(world.apply([Tick(now, 0)], now))
            thens.append((time.perf_counter() - t0) * 1e3)
        then_max.append(max(thens[-len(follow) :]))
        ticks = len(follow)
        t0 = time.perf_counter()
        sent = [job for out in [wave, *follow] for job in out.jobs]
        for job in sent:
            job.detach()  # what the node pays after publishing, when it sends them
        copies.append((time.perf_counter() - t0) * 1e3)
        directions, jobs = len(wave.directions), len(sent)
    return {
        "units": units,
        "threats": STORM_THREATS,
        "goals_apply_ms": goals_ms,
        "lookaheads": len(ms),
        "foresaw_trap_fraction": kinds["foreseen"] / max(1, len(ms)),
        "routes": kinds,
        "lookahead_cpu_ms": {
            "mean": float(ms.mean()) if len(ms) else None,
            "p50": float(np.median(ms)) if len(ms) else None,
            "p90": float(np.percentile(ms, 90)) if len(ms) else None,
            "max": float(ms.max()) if len(ms) else None,
        },
        "one_worker_s": float(ms.sum() / 1e3),
        "wave": {
            "apply_ms_median": statistics.median(waves),
            "apply_ms_all": waves,
            "held_off_gc_ms_median": statistics.median(afters),
            "then_ticks": ticks,
            "then_apply_ms_median": statistics.median(thens),
            "then_apply_ms_max": max(then_max),
            "job_copies_ms_median": statistics.median(copies),
            "directions": directions,
            "jobs": jobs,
        },
    }


def print_storm_and_wave(d: dict[str, Any]) -> None:
    """The two figures as ``pfp bench engine`` prints them."""
    c = d["lookahead_cpu_ms"]
    print(
        f"\ngoal storm, {d['units']} distinct goals x {d['threats']} threats, in process: "
        f"{d['lookaheads']} look-aheads ({d['foresaw_trap_fraction']:.0%} foresaw a trap; routes "
        f"{d['routes']['foreseen']} round a trap, {d['routes']['cheaper']} cheaper than descent), worker CPU "
        f"mean {c['mean']:.1f} ms (p50 {c['p50']:.1f}, p90 {c['p90']:.1f}, max {c['max']:.0f}); "
        f"one worker lands them all in {d['one_worker_s']:.1f} s"
    )
    wv = d["wave"]
    print(
        f"contingency wave, one threat ahead of {d['units']} units: World.apply median "
        f"{wv['apply_ms_median']:.1f} ms ({wv['directions']} directions; the collection it held off, "
        f"after: {wv['held_off_gc_ms_median']:.1f} ms; then their points and {wv['jobs']} jobs in "
        f"{wv['then_ticks']} more applies, median {wv['then_apply_ms_median']:.1f} ms, max "
        f"{wv['then_apply_ms_max']:.1f} ms; their stepper copies, paid when sent: "
        f"{wv['job_copies_ms_median']:.1f} ms)"
    )
