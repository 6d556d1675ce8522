"""What a direction says about the route a unit follows and the progress it makes (``docs/wire.md``).

Both are additive fields of ``Direction`` with a default of ``""`` (unknown),
so an older reader ignores them; their meanings, and what a vehicle should
do on each, are in the wire docs' status table.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["Progress", "RouteKind"]


class RouteKind(StrEnum):
    """What the route behind a direction is (``core.tracking.Route``, by value)."""

    NONE = ""  # no route yet: plain descent while one is computed (``deliberating``)
    DESCENT = "descent"
    LOWER_EXPOSURE = "lower_exposure"
    AROUND_TRAP = "around_trap"
    ESCAPE = "escape"
    LEAVE = "leave"


class Progress(StrEnum):
    """What the unit's own reports show of its motion (the planner's progress watch)."""

    UNKNOWN = ""  # too few reports yet, or the unit is not told to move
    MOVING = "moving"
    HOLDING = "holding"  # it says it is stopped (``speed_mps`` 0)
    STALLED = "stalled"  # told to move, it has not moved in the watch's window
