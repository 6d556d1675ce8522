"""A small fleet of the service bench's layout driven tick by tick, most of it on committed routes.

``walk(n, ticks)`` builds a world (deferred deliberation, run at once), puts
the layout's threats, reports the units, sets their goals and lands their
routes; then each tick moves every unit 5 m along its last direction,
reports it and lands what that deliberated, and yields the world, the ids
and the positions: the tests that compare a route's look-ahead with another
computation of it walk the same fleet.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from pfp_service.world.world import World

__all__ = ["walk"]


def walk(n: int, ticks: int) -> Iterator[tuple[World, list[str], np.ndarray]]:
    """``n`` units of ``benchmarks.service.layout`` (seed 7) for ``ticks`` ticks: ``(world, ids, positions)``."""
    from benchmarks.service import layout
    from pfp_service.core import PlannerParams
    from pfp_service.wire import Goal, UnitState
    from pfp_service.world.world import GoalSet, StateReported, ThreatPut, WorldSettings

    lay = layout(n, 100, 7)
    w = World(WorldSettings(planner=PlannerParams(), deliberation="deferred", unit_stale_s=1e9))
    w.apply([ThreatPut(t, u) for t, u in lay["threats"]], 0.0)
    ids = [f"u{i}" for i in range(n)]
    pos = np.array(lay["starts"][:n])
    w.apply([StateReported(u, UnitState(position=tuple(p), seq=0)) for u, p in zip(ids, pos)], 0.1)
    out = w.apply([GoalSet(u, Goal(position=g)) for u, g in zip(ids, lay["goals"][:n])], 0.2)
    out = w.apply([j.run() for j in out.jobs], 0.3)
    vec = {d.unit: d.vector for d in out.directions}
    for k in range(ticks):
        pos += 5.0 * np.array([vec.get(u, (0.0, 0.0)) for u in ids])
        states = [
            StateReported(u, UnitState(position=(float(x), float(y)), seq=k + 1))
            for u, (x, y) in zip(ids, pos)
        ]
        out = w.apply(states, 1.0 + 0.1 * k)
        w.apply([j.run() for j in out.jobs], 1.0 + 0.1 * k)
        vec.update({d.unit: d.vector for d in out.directions})
        yield w, ids, pos
