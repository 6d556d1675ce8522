"""A big tick after the warm-up, in a fresh interpreter: prints the numba kernels that gained a signature.

Run by tests/proc/test_warmup.py as ``python tests/warm_big_tick.py [--no-wide] [--units=N]``;
``--no-wide`` skips ``warmup.warm_wide``, to show that the tick does reach
kernels only the wide warm-up loads (the test can fail).  ``--units`` (600 by
default) sets the crowd: each size is a different random probe of the tick's
paths (150 reaches the zoned step rule and the clearance kernel, which 600
does not; 600 reaches the culled point level, which 150 does not), and its
cost grows faster than the count.
"""

from __future__ import annotations

import json
import sys

import numba
import numpy as np


def signatures() -> dict[str, int]:
    """Every numba dispatcher of pfp_service loaded so far, and how many signatures it holds."""
    out = {}
    for m in list(sys.modules.values()):
        if not (getattr(m, "__name__", "") or "").startswith("pfp_service"):
            continue
        for v in list(vars(m).values()):
            if isinstance(v, numba.core.dispatcher.Dispatcher):
                out[f"{v.py_func.__module__}.{v.py_func.__qualname__}"] = len(v.signatures)
    return out


def main() -> None:
    import pfp_service.node.previews as previews

    if "--no-wide" in sys.argv:
        previews.warm_wide = lambda base, terrain=True: None  # type: ignore[assignment]
    previews.warm_up(None)
    before = signatures()

    from pfp_service.terrain.grid import TerrainGrid
    from pfp_service.terrain.live import of_grid
    from pfp_service.wire import Goal, ThreatUpdate, UnitState
    from pfp_service.wire.messages import ZoneUpdate
    from pfp_service.world.events import GoalSet, StateReported, ThreatPut, Tick, WorldSettings, ZonePut
    from pfp_service.world.world import World

    rng = np.random.default_rng(7)
    xs = np.arange(121) * 20.0 - 1200.0
    gx, gy = np.meshgrid(xs, xs)
    ridge = 200.0 + 60.0 * np.exp(-((gx - 300.0) ** 2) / (2 * 80.0**2)) + 5.0 * np.sin(gy / 90.0)
    ground = of_grid(TerrainGrid(-1200.0, -1200.0, 20.0, ridge))
    world = World(WorldSettings(deliberation="inline", terrain=ground, bounds=ground.bounds))
    inputs: list = []
    for j in range(48):  # past cull.MIN_THREATS, each masked by its line of sight over the ridge
        where = (float(rng.uniform(-900, 900)), float(rng.uniform(-900, 900)))
        inputs.append(ThreatPut(f"t{j}", ThreatUpdate(position=where, sigma_range=40.0, sigma_lateral=25.0)))
    box = [(-60.0, 60.0), (60.0, 60.0), (60.0, -60.0), (-60.0, -60.0), (-60.0, -55.0)]
    box += [(55.0, -55.0), (55.0, 55.0), (-60.0, 55.0), (-60.0, 60.0)]
    inputs.append(ZonePut("box", ZoneUpdate(polygon=[box])))
    n = int(next((a.split("=", 1)[1] for a in sys.argv if a.startswith("--units=")), "600"))

    def far() -> tuple[float, float]:
        return float(rng.uniform(-1100, -700)), float(rng.uniform(-1100, -700))

    for u in range(n):
        goal = (float(rng.uniform(700, 1100)), float(rng.uniform(700, 1100)))
        inputs += [StateReported(f"u{u}", UnitState(position=far())), GoalSet(f"u{u}", Goal(position=goal))]
    for u in range(3):  # trapped in the box, one goal: a route search, then the shared grid
        inputs += [
            StateReported(f"in{u}", UnitState(position=(0.0, 10.0 * u))),
            GoalSet(f"in{u}", Goal(position=(400.0, 0.0))),
        ]
    world.apply(inputs, 0.0)
    reasons: set[str] = set()
    for k in range(1, 4):
        tick = [StateReported(f"u{u}", UnitState(position=far())) for u in range(n)]
        tick += [StateReported(f"in{u}", UnitState(position=(0.01 * k, 10.0 * u))) for u in range(3)]
        out = world.apply([*tick, Tick(float(k))], float(k))
        reasons |= {d.reason for d in out.directions if d.unit.startswith("in")}
    # a crowd with dispersion on, its units crossing within each other's separation, then a few reports a
    # tick as live: the tick's neighbour passes and a kept tree asked at the rows that moved
    from pfp_service.world.separations import DispersionSettings

    crowd = World(WorldSettings(deliberation="inline", dispersion=DispersionSettings(enabled=True)))
    spots = rng.uniform(-300.0, 300.0, (120, 2))
    first: list = []
    for u, (x, y) in enumerate(spots.tolist()):
        first += [
            StateReported(f"d{u}", UnitState(position=(x, y))),
            GoalSet(f"d{u}", Goal(position=(-x, -y))),
        ]
    crowd.apply(first, 0.0)
    for k in range(1, 4):
        for u in range(5):
            x, y = spots[u].tolist()
            crowd.apply([StateReported(f"d{u}", UnitState(position=(x + k, y)))], k + u / 10.0)
    after = signatures()
    grown = {k: [before.get(k, 0), v] for k, v in after.items() if v != before.get(k, 0)}
    print(json.dumps({"grown": grown, "reasons": sorted(reasons)}))


if __name__ == "__main__":
    main()
