"""A team role's say as a unit's direction: held, towards a point, and kept clear of zones.

The team book (``team_book``) decides what each member's roles say; these turn that into the
``Direction`` the unit is sent.  Pure: a direction in, a direction out.
"""

from __future__ import annotations

import math

import msgspec

from pfp_service.core.steprule import CLEAR_STEPS
from pfp_service.core.zones import ZoneSet, clear_run
from pfp_service.wire import Direction
from pfp_service.world.teams import Point
from pfp_service.world.units import UnitRecord

__all__ = ["held", "kept_clear", "towards"]


def held(d: Direction, reason: str) -> Direction:
    return msgspec.structs.replace(
        d,
        vector=(0.0, 0.0),
        heading_deg=None,
        reach_m=0.0,
        lookahead=[],
        reason=reason[:1024],
    )


def kept_clear(d: Direction, rec: UnitRecord, zs: ZoneSet) -> Direction:
    """A role's step cut short of the first zone or barrier on its way, as the planner's own steps are
    (``steprule.CLEAR_STEPS`` short); held where its way touches one at once.  A unit already in one
    keeps the role's step: the planner's way out is its own step's business."""
    assert rec.position is not None
    if not zs.zones or not d.reach_m or zs.zone_at(*rec.position):
        return d
    clear = CLEAR_STEPS * (rec.stepper.params.step if rec.stepper is not None else 1.0)
    run = clear_run(zs, *rec.position, *d.vector, d.reach_m, clear)
    if run >= d.reach_m:
        return d
    if run <= 0.0:
        return held(d, f"{d.reason}; a keep-out zone or barrier in the way")
    return msgspec.structs.replace(d, reach_m=run)


def towards(d: Direction, at: Point, to: Point, reason: str) -> Direction:
    dx, dy = to[0] - at[0], to[1] - at[1]
    far = math.hypot(dx, dy)
    if far <= 0.0:
        return held(d, reason)
    heading = math.degrees(math.atan2(dx, dy)) % 360.0
    return msgspec.structs.replace(
        d,
        vector=(dx / far, dy / far),
        heading_deg=0.0 if heading >= 360.0 else heading,
        reach_m=far,
        lookahead=[],
        reason=reason[:1024],
    )
