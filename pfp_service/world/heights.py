"""The heights threats over terrain see the units at: who a change reaches, each unit judged at its own.

A threat's window is swept once, at the planner's class's height, and
serves every unit (``core.visibility.Window.at``: the same heights under
another target height); a unit is seen at its own height, its class's or
its override (``world.mobility.height_of``, ``team_route.RouteKeys.height``).  A threat
put reaches a unit only where it sees it at that height
(``reach.reached``), judged once per height, never per unit.
"""

from __future__ import annotations

from collections.abc import Sequence

from pfp_service.core import Threat
from pfp_service.core.visibility import AtHeight, Sight
from pfp_service.world.reach import reached
from pfp_service.world.units import UnitRecord
from pfp_service.world.wave import Judged, reached_with

__all__ = ["reached_seen"]


def reached_seen(
    guided: list[UnitRecord],
    heights: Sequence[float | None],
    touched: list[Threat],
    intensity: str,
    zones: Sequence[tuple[float, float, float, float]] = (),
    sight: Sight | None = None,
    wide: Sequence[bool] | None = None,
    judged: Sequence[Judged] = (),
) -> list[bool]:
    """``reach.reached``, each unit judged at the height a threat sees it at (``heights[i]``; ``None``:
    ``sight``'s own), one call per height.  When every unit is at ``sight``'s own height, the verdicts
    ``judged`` off the loop with the windows serve for the units unchanged since (``wave.reached_with``)."""
    if sight is None or all(h is None for h in heights):
        if judged and wide is not None:
            return reached_with(judged, guided, list(wide), touched, intensity, zones, sight)
        return reached(guided, touched, intensity, zones, sight, wide)
    out, groups = [False] * len(guided), dict[float | None, list[int]]()
    for i, h in enumerate(heights):
        groups.setdefault(h, []).append(i)
    for h, idx in groups.items():
        at = sight if h is None else AtHeight(sight, h)
        part = None if wide is None else [wide[i] for i in idx]
        for i, hit in zip(idx, reached([guided[i] for i in idx], touched, intensity, zones, at, part)):
            out[i] = hit
    return out
