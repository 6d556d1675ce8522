"""A team's goal: each member's place (a formation's offsets, else the column), and the team's ETA.

The commander gives a team one goal (``TeamUpdate.goal``); ``places`` gives
each member its own goal from it, which the world sets as if each had been
put on the member's goal key.  A member listed in ``offsets`` goes to the
goal moved by its offset.  Every other member is placed in column order (the
lead, the followers in their order, then the rest as the team lists them):
the ``i``-th goes to the team's goal itself and arrives within ``i *
spacing_m`` more of it.  A follower's place is then where it first comes
within that distance of the goal, along ground its lead crossed on its own way
to the goal: a column place is on the cleared corridor by construction, and a
follower never holds for a place outside it (docs/teams.md).

``eta`` is the team's time to arrive: its slowest member's, each member's
the straight distance left to its arrival circle over the speed its reports
show.  Pure: positions, goals and speeds come from the world's records.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import msgspec

from pfp_service.wire import DirectionStatus, Goal
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.units import UnitRecord

__all__ = ["COLUMN_SPACING_M", "MOVING_MPS", "column", "eta", "places", "placing_changed"]

# The column's spacing when a team states neither spacing_m nor separation_m: the issue's
# vehicles on a tactical march.
COLUMN_SPACING_M = 50.0
MOVING_MPS = 0.1  # a member slower than this is not moving: its ETA is unknown, and so is the team's


def column(team: TeamUpdate) -> list[str]:
    """The members placed in column (those without an offset): the lead, the followers, then the rest."""
    order = [team.lead, *team.follow, *team.units()]
    return [u for u in dict.fromkeys(order) if u is not None and u not in team.offsets]


def places(team: TeamUpdate) -> dict[str, Goal]:
    """Each member's goal from the team's goal (none without one), in the team's order of members."""
    goal = team.goal
    if goal is None:
        return {}
    spacing = team.spacing_m or team.separation_m or COLUMN_SPACING_M
    out: dict[str, Goal] = {}
    for i, u in enumerate(column(team)):
        tol = goal.tolerance if i == 0 else (goal.tolerance or 0.0) + i * spacing
        out[u] = msgspec.structs.replace(goal, tolerance=tol)
    gx, gy = goal.position
    for u, (dx, dy) in team.offsets.items():
        out[u] = msgspec.structs.replace(goal, position=(gx + dx, gy + dy))
    return out


def eta(team: TeamUpdate, units: Mapping[str, UnitRecord]) -> tuple[float | None, str | None]:
    """``(eta_s, slowest)``: the slowest member's time to arrive and its id.

    Members with no goal are not counted; an arrived one counts 0 s.  A member lost, stale or not
    moving has no ETA: the team's is then ``None``, and ``slowest`` names that member.
    """
    worst: tuple[float, str] | None = None
    for u in team.units():
        rec = units.get(u)
        if rec is None or rec.goal is None:
            continue
        if rec.last_status is DirectionStatus.ARRIVED:
            t = 0.0
        else:
            speed = rec.progress.speed_mps
            if rec.position is None or rec.stale or not speed >= MOVING_MPS:
                return None, u
            left = math.dist(rec.position, rec.goal.position) - (rec.goal.tolerance or 0.0)
            t = max(left, 0.0) / speed
        if worst is None or t > worst[0]:
            worst = (t, u)
    return (worst[0], worst[1]) if worst is not None else (None, None)


def placing_changed(old: TeamUpdate | None, new: TeamUpdate) -> bool:
    """Whether a team put gives its members new places: a goal new, moved, or placed otherwise."""
    if new.goal is None or old is None:
        return new.goal is not None
    was, now = [(t.goal, t.offsets, t.spacing_m, t.separation_m, column(t)) for t in (old, new)]
    return was != now
