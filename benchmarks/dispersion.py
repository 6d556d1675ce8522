"""Dispersion in crowds: separation kept, arrivals, deadlocks cleared, arrival-time and tick cost, with and without.

Seeded crowds driven through the sans-I/O world in process
(``benchmarks._crowd.simulate``: every unit reports each simulated second,
drives along its direction at 5 m/s, deliberation runs between ticks):
200 vehicles through a line of threats with three gaps, and 1,000 vehicles
whose goals converge to a grid 0.6 the size of their start (``_crowd``).  Each crowd runs
twice, without and with dispersion (defaults: 50 m between vehicles), and
the figures are measured on the tracks.

Targets: no two units closer than their separation less 10 %; every unit
that arrives without dispersion arrives with it; every deadlock cleared
within 30 s of simulated time, measured on the tracks two ways: from the
deadlock's start (the unit held or came no nearer its goal) until each of
its two units is nearer its goal than it was then (``_crowd.CLEARED``) or
rests, and a unit's longest stretch of yielding that had a deadlock in it;
and on the 1,000-unit crowd, the tick's CPU per state
report with dispersion at most 1.2 times without, timed on identical inputs
(a shadow world with dispersion fed the same reports, ``simulate(shadow=)``).
"""

from __future__ import annotations

import argparse
import os
import sys

TARGET_SHARE = 0.9  # of the separation, at the closest
TARGET_DEADLOCK_S = 30.0
TARGET_CPU = 1.2


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="60 units through the gaps and 300 converging")
    p.add_argument("--seed", type=int, default=1, help="seeds the crowds (default: 1)")
    p.add_argument("--check", action="store_true", help="exit 1 when a target is missed")


def run(args: argparse.Namespace) -> int:
    from benchmarks import _crowd
    from pfp_service.world.separations import DispersionSettings

    on = DispersionSettings(enabled=True)
    crowds = [_crowd.gaps(60 if args.quick else 200, seed=args.seed)]
    crowds.append(_crowd.converging(300 if args.quick else 1000, seed=args.seed + 1))
    print(f"pfp bench dispersion: load average {_load()} at the start", flush=True)
    missed: list[str] = []
    for crowd in crowds:
        off = _crowd.simulate(crowd, None, shadow=on)
        with_ = _crowd.simulate(crowd, on)
        missed += _report(crowd, off, with_)
    print(f"load average {_load()} at the end")
    for m in missed:
        print(f"MISSED: {m}")
    return 1 if args.check and missed else 0


def _report(crowd, off, on) -> list[str]:  # type: ignore[no-untyped-def]
    n = len(crowd.starts)
    reach = set(off.arrived_s)
    lost = sorted(reach - set(on.arrived_s))
    both = sorted(reach & set(on.arrived_s))
    mean_off = sum(off.arrived_s[u] for u in both) / max(len(both), 1)
    mean_on = sum(on.arrived_s[u] for u in both) / max(len(both), 1)
    last_off, last_on = max(off.arrived_s.values(), default=0.0), max(on.arrived_s.values(), default=0.0)
    cpu_off = sum(off.tick_cpu_s) / max(off.states, 1) * 1e6
    cpu_on = sum(off.shadow_cpu_s) / max(off.states, 1) * 1e6
    print(f"\n{crowd.name} (seeded), {n} units, 50 m separation")
    print(
        f"  closest pair: {off.closest_m:.1f} m without, {on.closest_m:.1f} m with ({on.closest_share:.2f} of it)"
    )
    print(
        f"  arrived: {len(off.arrived_s)}/{n} without, {len(on.arrived_s)}/{n} with; reachable not arriving: {len(lost)}"
    )
    print(
        f"  arrival time, the units arriving in both: mean {mean_off:.0f} s -> {mean_on:.0f} s "
        f"({mean_on / max(mean_off, 1e-9):.2f}x), last {last_off:.0f} s -> {last_on:.0f} s"
    )
    print(
        f"  deadlocks: {on.deadlocks}; longest yielding with one in it: {on.longest_deadlock_s:.0f} s; "
        f"longest yielding: {on.longest_hold_s:.0f} s; still holding at the end: {on.still_holding}"
    )
    print(
        f"  deadlocks cleared (both units nearer their goals, on the tracks): longest {on.longest_clearing_s:.0f} s"
        f" from its start; not cleared by the end: {on.not_cleared}"
    )
    print(
        f"  tick CPU per state, identical inputs: {cpu_off:.1f} us without, {cpu_on:.1f} us with "
        f"({cpu_on / max(cpu_off, 1e-9):.2f}x)"
    )
    missed = []
    if on.closest_share < TARGET_SHARE:
        missed.append(
            f"{crowd.name}: closest pair {on.closest_share:.2f} of the separation (target >= {TARGET_SHARE})"
        )
    if lost:
        missed.append(f"{crowd.name}: {len(lost)} reachable units did not arrive ({', '.join(lost[:5])})")
    if on.longest_deadlock_s > TARGET_DEADLOCK_S or on.still_holding:
        missed.append(
            f"{crowd.name}: a deadlock lasted {on.longest_deadlock_s:.0f} s, {on.still_holding} still held"
        )
    if on.longest_clearing_s > TARGET_DEADLOCK_S or on.not_cleared:
        missed.append(
            f"{crowd.name}: a deadlock took {on.longest_clearing_s:.0f} s to clear, {on.not_cleared} not cleared"
        )
    if n >= 1000 and cpu_on > TARGET_CPU * cpu_off:
        missed.append(f"{crowd.name}: tick CPU {cpu_on / cpu_off:.2f}x (target <= {TARGET_CPU}x)")
    return missed


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


if __name__ == "__main__":
    sys.exit(run(argparse.Namespace(quick=True, seed=1, check=False)))
