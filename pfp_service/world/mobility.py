"""A unit's mobility class, as its state and its goal name it: the slope limit its barriers are made for.

A unit's state may carry a ``mobility`` (``wire.GoalMobility``): its standing
class, kept on its record until a state names another (a state without one
changes nothing, so the 5,000 states a second pay nothing for it).  A goal
may carry one too: it overrides the standing class for that goal (a team's
goal with one overrides each member's; without one each member keeps its
own).  Absent both, the planner's class (``--terrain-unit``).  A class is a
class of ``core.mobility.CLASSES`` and optionally its ``max_slope_deg``
overridden.  Over terrain the unit then plans around the ground steeper than
that limit (``terrain.live.LiveTerrain.barriers``) instead of the planner's
class's; without terrain it changes nothing.  An override is the unit's own
limit, to the whole degree (``slope_limit``): its barriers are built off the
loop when first wanted and held by the world (``world.slopes``), the unit
planned meanwhile at the steepest class limit not above it (the safe side),
and re-judged at its own when they land.  An override below every class's
limit is refused: no set is held to plan it at meanwhile.  A state that
changes the limit a unit wants re-judges it at once (``units.Units.classed``).
Its ``height_m`` and ``speed_mps`` override the class's too, as the
scenario's ``unit:`` block's do (``core.mobility.Mobility.merged``;
``mobility_of``).  A threat's window is swept once, at the planner's
class's height, and serves every unit: a unit is seen at its own height
(``height_of``: its class's, or its override at the next quarter metre
up, ``core.mobility.planned_height``), its field the world's
re-heighted (``world_records.Records.field_for``); a controller's link is
judged from the controller's own height to the robot's (``team_book``).
"""

from __future__ import annotations

import math
from typing import Any, TypeVar

from pfp_service.core.mobility import CLASS_LIMITS, CLASSES, Mobility, planned_height, planned_limit
from pfp_service.errors import InputError
from pfp_service.wire import Goal, GoalMobility, UnitState
from pfp_service.wire.messages.structs import FLAT_SPEED_MPS, UNIT_HEIGHT_M

__all__ = [
    "by_limit",
    "check",
    "height_of",
    "limit_of",
    "mobility_of",
    "own_height",
    "own_speed",
    "refusal",
    "sight_height",
    "slope_limit",
]

M = TypeVar("M", Goal, UnitState)


def refusal(msg: Goal | UnitState) -> InputError | None:
    """Why ``msg`` (a goal or a state) is refused for its mobility class (``$.mobility.class``: not one of
    ``CLASSES``; ``$.mobility.max_slope_deg``: below every class limit), or ``None``."""
    mob = msg.mobility
    if mob is None:
        return None
    if mob.kind not in CLASSES:
        return InputError(
            "$.mobility.class", f"unknown mobility class {mob.kind!r} (one of {', '.join(CLASSES)})"
        )
    if mob.max_slope_deg is not None and planned_limit(mob.max_slope_deg) is None:
        return InputError(
            "$.mobility.max_slope_deg",
            f"{mob.max_slope_deg:g} is below {CLASS_LIMITS[0]}, the gentlest class limit (a unit plans at it while its own barriers are built)",
        )
    return None


def check(msg: M) -> M:
    """``msg`` (a goal or a state), if its mobility class is one the planner knows.

    Raises:
        InputError: as ``refusal`` says.
    """
    mob = msg.mobility
    if mob is None or (mob.max_slope_deg is None and mob.kind in CLASSES):  # the states' hot path
        return msg
    refused = refusal(msg)
    if refused is not None:
        raise refused
    return msg


def slope_limit(goal: Goal | None, standing: GoalMobility | None = None) -> int | None:
    """The whole degrees of slope a unit climbs toward ``goal``: its goal's class, else its ``standing`` one
    (its states'), else ``None``: the planner's class's (a class unknown too: refused, ``refusal``).  An
    override is its own limit rounded (planned at it once its set is held, ``world.slopes``); one below
    every class's limit (refused on the wire) is ``None``."""
    mob = goal.mobility if goal is not None and goal.mobility is not None else standing
    if mob is None or mob.kind not in CLASSES:
        return None
    limit = mob.max_slope_deg
    if limit is None or not math.isfinite(limit):  # the class's (a NaN put in-process: no limit of its own)
        return planned_limit(CLASSES[mob.kind].max_slope_deg)
    return round(limit) if planned_limit(limit) is not None else None


def limit_of(rec: Any) -> int | None:
    """``slope_limit`` of a unit's record (``units.UnitRecord``): its goal's class over its states'."""
    return slope_limit(rec.goal, rec.mobility)


def sight_height(goal: Goal | None, standing: GoalMobility | None = None) -> float | None:
    """How tall a unit heading for ``goal`` stands, metres: what a threat must see of it
    (``core.mobility.Mobility.height_m``), its goal's mobility over its ``standing`` one (its states'),
    its ``height_m`` over its class's (planned at ``core.mobility.planned_height``: near heights share a
    field); ``None``: the planner's class's."""
    mob = goal.mobility if goal is not None and goal.mobility is not None else standing
    if mob is None or mob.kind not in CLASSES:
        return None
    own = own_height(mob)
    return planned_height(own) if own is not None else CLASSES[mob.kind].height_m


def mobility_of(goal: Goal | None, standing: GoalMobility | None = None) -> Mobility | None:
    """The whole mobility of a unit heading for ``goal`` (``core.mobility.Mobility``): its goal's over its
    ``standing`` one (its states'), each field given overriding its class's; ``None``: the planner's class."""
    mob = goal.mobility if goal is not None and goal.mobility is not None else standing
    if mob is None or mob.kind not in CLASSES:
        return None
    return CLASSES[mob.kind].merged(mob.max_slope_deg, own_height(mob), own_speed(mob))


def own_height(mob: GoalMobility) -> float | None:
    """``mob``'s ``height_m`` override, or ``None``: none, or one the wire's bounds refuse (put in-process:
    its class's then, never a NaN in a field)."""
    h = mob.height_m
    return h if h is not None and UNIT_HEIGHT_M[0] <= h <= UNIT_HEIGHT_M[1] else None


def own_speed(mob: GoalMobility) -> float | None:
    """``mob``'s ``speed_mps`` override, or ``None``: none, or one the wire's bounds refuse (as ``own_height``)."""
    v = mob.speed_mps
    return v if v is not None and FLAT_SPEED_MPS[0] <= v <= FLAT_SPEED_MPS[1] else None


def height_of(rec: Any) -> float | None:
    """``sight_height`` of a unit's record (``units.UnitRecord``): its goal's class over its states'."""
    return sight_height(rec.goal, rec.mobility)


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
        groups.setdefault(limit_of(rec), ([], []))[0].append(rec)
    for item in owed:
        groups.setdefault(limit_of(item[0]), ([], []))[1].append(item)
    return groups
