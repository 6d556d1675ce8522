"""The teams world in process on ``pfp bench service --teams``' march: CPU per state, and a hash of its directions.

No Zenoh: ``World.apply`` (inline deliberation, the planner's own settings, with
``--dispersion`` and a team for every four units, or plain) is driven on the
march of ``benchmarks/_service_teams.py`` as the bench's load generator drives
the live planner: every unit reports in turn, ``TICK`` reports a tick at
``RATE_PER_S`` (so a tick is ``TICK / RATE_PER_S`` s of the world's time), and
each unit moves ``STEP_M`` along the last vector it was given while moving.
After ``WARM`` ticks, each tick's ``World.apply`` is timed with the thread's CPU
clock; then the contingency wave (``pfp bench service``'s fan-out: a threat put
just ahead of the units' centre) is one ``World.apply``, timed alike.  The hash covers every direction (every field, the reason included) and
event of every tick, warm ones included: two trees that give the same hash on
the same seed made the same decisions.

Run as ``python -m benchmarks._march_world [--teams-only] [--ticks N] [--tick N] [--rounds R] [--waves W] [--profile FILE]``;
``--rounds`` alternates plain and teams worlds in one run; ``--waves`` puts and removes the threat
``W`` more times, each wave's CPU apart (a median of several is steadier than one).
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import hashlib
import json
import os
import statistics
import time
from typing import Any

import msgspec

__all__ = ["drive"]

UNITS = 1000
TICK = 256  # reports a tick: the live planner's ticks when it is busy at this rate
RATE_PER_S = 5000.0  # TARGETS["cpu_rate_per_s"]
WARM = 60
MISSION = "bench"


def _world(teams: bool) -> Any:
    """The world ``pfp serve`` (with ``--dispersion`` for teams) makes, deliberating inline."""
    import dataclasses

    from pfp_service.node.config import ServeConfig
    from pfp_service.world.world import World

    settings = ServeConfig(mission=MISSION, dispersion=teams).world_settings()
    return World(dataclasses.replace(settings, deliberation="inline"))


def drive(
    teams: bool,
    ticks: int,
    seed: int = 2023,
    profile: str | None = None,
    waves: int = 0,
    tick: int = TICK,
) -> dict[str, Any]:
    """One world: ``WARM`` ticks, then ``ticks`` timed; CPU us per state and the hash of every output.

    ``waves``: after the contingency wave, that many more put and removed in turn (the threat 5 m
    further each put, 10 ms of the world's time apart), each until none of its shares is owed: the
    CPU of each, its collections included (their directions join the hash).  ``tick``: reports a tick
    (the world's time a tick is ``tick / RATE_PER_S`` s); the live planner's ticks at ``pfp bench
    service``'s steady rate are a few states each, where a tick's work over the whole fleet weighs."""
    from benchmarks._layout import layout
    from benchmarks._phases import STEP_M
    from benchmarks._service_teams import march
    from benchmarks._service_teams import teams as make_teams
    from pfp_service.wire import Goal, UnitState
    from pfp_service.world.events import Tick
    from pfp_service.world.world import GoalSet, StateReported, TeamPut, ThreatPut, ThreatRemoved

    lay = march(UNITS, layout(UNITS, 100, seed)["threats"], seed)
    ids = [f"u{i}" for i in range(UNITS + 1)]
    pos = [list(p) for p in lay["starts"]]
    vec: dict[str, tuple[float, float]] = {}
    w = _world(teams)
    digest = hashlib.sha256()
    judge_s = [0.0]
    judge = w.teams.judge

    def judged(*args: Any, **kw: Any) -> Any:  # the roles' share of the ticks: the team book's judge alone
        c0 = time.thread_time()
        try:
            return judge(*args, **kw)
        finally:
            judge_s[0] += time.thread_time() - c0

    w.teams.judge = judged

    def take(out: Any) -> None:
        for d in out.directions:
            digest.update(msgspec.json.encode(d))
            vec[d.unit] = d.vector if d.status in ("en_route", "escaping") else (0.0, 0.0)
        for e in out.events:
            digest.update(msgspec.json.encode(e))

    now = 0.0
    take(w.apply([ThreatPut(t, u) for t, u in lay["threats"]], now))
    take(
        w.apply([StateReported(u, UnitState(position=tuple(pos[i]), seq=0)) for i, u in enumerate(ids)], now)
    )
    if teams:
        take(w.apply([TeamPut(t, u) for t, u in make_teams(lay, UNITS).items()], now))
    take(w.apply([GoalSet(u, Goal(position=lay["goals"][i], step=STEP_M)) for i, u in enumerate(ids)], now))
    nxt, seq, cpu, states = 0, 1, 0.0, 0
    prof = None
    gc_s, gc_at = [0.0], [0.0]

    def collected(phase: str, info: dict[str, int]) -> None:  # the collector's CPU, inside the timed ticks
        if phase == "start":
            gc_at[0] = time.thread_time()
        else:
            gc_s[0] += time.thread_time() - gc_at[0]

    gc.callbacks.append(collected)
    warm = WARM * TICK // tick  # as many reports warm whatever the tick's size
    for t in range(warm + ticks):
        batch = []
        for _ in range(tick):
            i, nxt = nxt, (nxt + 1) % len(ids)
            vx, vy = vec.get(ids[i], (0.0, 0.0))
            pos[i][0] += STEP_M * vx
            pos[i][1] += STEP_M * vy
            batch.append(StateReported(ids[i], UnitState(position=(pos[i][0], pos[i][1]), seq=seq)))
            seq += 1
        now += tick / RATE_PER_S
        if t == warm and profile:
            prof = cProfile.Profile()
            prof.enable()
        if t == warm:
            gc_s[0] = judge_s[0] = 0.0
        c0 = time.thread_time()
        out = w.apply(batch, now)
        if t >= warm:
            cpu += time.thread_time() - c0
            states += len(batch)
        else:
            gc_s[0] = 0.0
        take(out)
    # the contingency wave, as ``pfp bench service``'s fan-out puts it: one threat just ahead of the centre
    from pfp_service.wire import ThreatUpdate

    at = (statistics.median(p[0] for p in pos) + 60.0, statistics.median(p[1] for p in pos))
    threat = ThreatUpdate(position=at, facing_deg=270.0, sigma_range=40.0, sigma_lateral=28.0, skew=2.0)
    for r in w._units.values():  # deliberation deferred, as in the live planner: the wave, not its searches
        if r.stepper is not None:
            r.stepper.defer = True
    if prof is not None:
        prof.disable()
        prof.dump_stats(profile)  # type: ignore[arg-type]
        prof = cProfile.Profile()
        prof.enable()
        profile = f"{profile}.wave"
    told: set[str] = set()
    tick_gc_s, gc_s[0] = gc_s[0], 0.0
    tick_judge_s = judge_s[0]
    c0 = time.thread_time()
    out = w.apply([ThreatPut("contingency", threat)], now)
    wave_s = time.thread_time() - c0
    take(out)
    told.update(d.unit for d in out.directions)
    for _ in range(1000):  # the wave's later shares, each the next ``apply`` (a Tick, as the node's wake)
        if not w.wave_pending():
            break
        c0 = time.thread_time()
        out = w.apply([Tick(now)], now)
        wave_s += time.thread_time() - c0
        take(out)
        told.update(d.unit for d in out.directions)
    put_ms: list[float] = []
    removed_ms: list[float] = []
    for k in range(waves):  # more waves on the same world: a wave's CPU is noisy, a median of several is not
        for put in (True, False):
            now += 0.01
            moved = msgspec.structs.replace(threat, position=(at[0], at[1] + 5.0 * k))
            c0 = time.thread_time()
            take(w.apply([ThreatPut("contingency", moved) if put else ThreatRemoved("contingency")], now))
            while w.wave_pending():
                take(w.apply([Tick(now)], now))
            (put_ms if put else removed_ms).append(round(1e3 * (time.thread_time() - c0), 1))
    gc.callbacks.remove(collected)
    if prof is not None:
        prof.disable()
        prof.dump_stats(profile)  # type: ignore[arg-type]
    return (
        {
            "us_per_state": 1e6 * cpu / max(states, 1),
            "judge_us_per_state": 1e6 * tick_judge_s / max(states, 1),
            "gc_us_per_state": 1e6
            * tick_gc_s
            / max(states, 1),  # the collector's share (also outside ``apply``)
            "wave_ms": 1e3 * wave_s,
            "wave_gc_ms": 1e3
            * gc_s[0],  # a full collection (~0.1 s) lands in a wave or not: the wave less it
            "wave_units": len(told),
            "hash": digest.hexdigest()[:16],
        }
        | ({"waves_put_ms": put_ms, "waves_removed_ms": removed_ms} if waves else {})
    )


def main() -> None:
    p = argparse.ArgumentParser(prog="python -m benchmarks._march_world")
    p.add_argument("--ticks", type=int, default=60, help="timed ticks after the warm ones (default 60)")
    p.add_argument("--rounds", type=int, default=1, help="plain and teams worlds alternating (default 1)")
    p.add_argument("--teams-only", action="store_true", help="only the teams world")
    p.add_argument("--seed", type=int, default=2023)
    p.add_argument(
        "--tick", type=int, default=TICK, help=f"reports a tick (default {TICK}; the live bench's are a few)"
    )
    p.add_argument(
        "--waves", type=int, default=0, help="then that many threats put and removed in turn (default 0)"
    )
    p.add_argument(
        "--profile",
        help="with --teams-only: cProfile the timed ticks into this file, the wave into FILE.wave",
    )
    a = p.parse_args()
    for r in range(a.rounds):
        row: dict[str, Any] = {"round": r + 1, "loadavg": os.getloadavg()[0]}
        for kind in ("teams",) if a.teams_only else ("plain", "teams"):
            row[kind] = drive(
                kind == "teams", a.ticks, a.seed, a.profile if a.teams_only else None, a.waves, a.tick
            )
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
