"""A controller's link judged at each end's own height: the controller's mast and the robot's, from their mobility.

Over terrain the link needs a clear line of sight (``teams.link``), and whether a crest hides a robot
depends on how tall each end stands: a controller on foot (1.8 m) and a robot with a 4 m mast see
over a ridge a planner's class's 2.5 m at both ends does not.  Each end stands at its own unit's
height (as ``world.mobility.mobility_of`` says it: its goal's mobility over its states', an override
of ``height_m`` over its class's, to the centimetre: a sight line is a profile of the DEM, asked anew
each time, so no height costs more than another), else at the planner's class's.  The sight a link
is asked with (``teams.Sight``) takes the controller's point first and the robot's second; a sight
that cannot set its ends' heights (a test's, or none without terrain) is used as it is.  Pure:
records in, sights out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from pfp_service.core.mobility import CLASSES
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.mobility import own_height
from pfp_service.world.teams import Point, Sight

__all__ = ["height", "pair", "per_robot"]


def height(units: Mapping[str, Any], unit: str | None) -> float | None:
    """How tall ``unit`` stands for its link, metres (its mobility's ``height_m``); ``None``: the class's."""
    rec = units.get(unit) if unit is not None else None
    if rec is None or (rec.mobility is None and (rec.goal is None or rec.goal.mobility is None)):
        return None  # no mobility named (the common case): the planner's class
    mob = rec.goal.mobility if rec.goal is not None and rec.goal.mobility is not None else rec.mobility
    if mob.kind not in CLASSES:
        return None
    own = own_height(mob)
    return own if own is not None else CLASSES[mob.kind].height_m


def pair(sight: Sight | None, units: Mapping[str, Any], team: TeamUpdate, robot: str) -> Sight | None:
    """``sight`` from ``team``'s controller's height to ``robot``'s (``sight`` itself when both are the
    class's, or ``robot`` is none of its robots)."""
    between = getattr(sight, "between", None)
    if between is None or robot not in team.robots:
        return sight
    c_m, r_m = height(units, team.controller), height(units, robot)
    return sight if c_m is None and r_m is None else between(c_m, r_m)


def per_robot(
    sight: Sight | None, units: Mapping[str, Any], controller: str | None, robots: Sequence[tuple[str, Point]]
) -> dict[str, Sight] | None:
    """Each robot's own sight line from ``controller``, where its end or the controller's is not the class's
    height (``pair``); ``None`` when none is."""
    between = getattr(sight, "between", None)
    if between is None:
        return None
    c_m = height(units, controller)
    own = {rid: height(units, rid) for rid, _ in robots}
    out = {rid: between(c_m, r_m) for rid, r_m in own.items() if c_m is not None or r_m is not None}
    return out or None
