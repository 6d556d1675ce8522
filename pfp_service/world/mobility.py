"""A unit's mobility class, as its goal names it: the slope limit its barriers are made for.

A goal may carry a ``mobility`` (``wire.GoalMobility``): a class of
``core.mobility.CLASSES`` and optionally its ``max_slope_deg`` overridden.
Over terrain the unit then plans around the ground steeper than that limit
(``terrain.live.LiveTerrain.barriers``) instead of the planner's class's
(``--terrain-unit``); without terrain it changes nothing.  The limit is
planned at a class's limit (``core.mobility.CLASS_LIMITS``): an override at
the steepest of them not above it, the safe side, since a barrier set for a
new limit takes seconds to build over a large DEM and none is built on the
live loop; an override below every class's limit is refused.  Sight stays the planner's class's:
a threat's line of sight is computed once for every unit, at that height.
"""

from __future__ import annotations

from typing import Any

from pfp_service.core.mobility import CLASS_LIMITS, CLASSES, planned_limit
from pfp_service.errors import InputError
from pfp_service.wire import Goal

__all__ = ["by_limit", "check", "refusal", "slope_limit"]


def refusal(goal: Goal) -> InputError | None:
    """Why ``goal`` is refused for its mobility class (``$.mobility.class``: not one of ``CLASSES``), or ``None``."""
    mob = goal.mobility
    if mob is not None and mob.kind not in CLASSES:
        return InputError(
            "$.mobility.class", f"unknown mobility class {mob.kind!r} (one of {', '.join(CLASSES)})"
        )
    if mob is not None and mob.max_slope_deg is not None and planned_limit(mob.max_slope_deg) is None:
        return InputError(
            "$.mobility.max_slope_deg",
            f"{mob.max_slope_deg:g} is below {CLASS_LIMITS[0]}, the gentlest class limit the planner holds barriers for",
        )
    return None


def check(goal: Goal) -> Goal:
    """``goal``, if its mobility class is one the planner knows.

    Raises:
        InputError: as ``refusal`` says.
    """
    refused = refusal(goal)
    if refused is not None:
        raise refused
    return goal


def slope_limit(goal: Goal | None) -> int | None:
    """The whole degrees of slope the goal's unit climbs, or ``None``: the planner's class's (a class
    unknown too: its goal is refused, ``refusal``)."""
    mob = goal.mobility if goal is not None else None
    if mob is None or mob.kind not in CLASSES:
        return None
    limit = mob.max_slope_deg if mob.max_slope_deg is not None else CLASSES[mob.kind].max_slope_deg
    return planned_limit(limit)


def by_limit(
    guided: list[Any], owed: list[tuple[Any, Any]], terrain: bool = True
) -> dict[int | None, tuple[list[Any], list[Any]]]:
    """The units to steer (records) and those owed their points (``(record, advice)``) by their slope limit,
    each in the order given: each group is steered under its own field (``Records.field_for``).  Without
    ``terrain`` a class changes nothing: one group, as given."""
    if not terrain:
        return {None: (guided, owed)}
    groups: dict[int | None, tuple[list[Any], list[Any]]] = {}
    for rec in guided:
        groups.setdefault(slope_limit(rec.goal), ([], []))[0].append(rec)
    for item in owed:
        groups.setdefault(slope_limit(item[0].goal), ([], []))[1].append(item)
    return groups
