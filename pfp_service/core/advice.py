"""What the stepper says: a unit's status, its advice, and the deliberation it asks for.

Plain values (``NamedTuple``s and a ``StrEnum``), shared by the stepper
(``core.stepper``), the batch that advises many units at once
(``core.batch``), the drivers (``core.plan``, the live world) and the
look-ahead.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import NamedTuple

from pfp_service.core.tracking import Route

__all__ = ["Advice", "Need", "StepStatus"]


class StepStatus(StrEnum):
    """What the stepper says about the unit at this position."""

    EN_ROUTE = "en_route"
    ESCAPING = "escaping"
    ARRIVED = "arrived"
    TRAPPED = "trapped"
    OUT_OF_BOUNDS = "out_of_bounds"
    INVALID = "invalid"

    terminal: bool  # the unit is no longer moving: set on each member below (read per advice, so no property)


for _status in StepStatus:
    _status.terminal = _status not in (StepStatus.EN_ROUTE, StepStatus.ESCAPING)


class Advice(NamedTuple):
    """One answer of the stepper.

    ``dx, dy`` is a unit vector (``0, 0`` when the status is terminal);
    ``level`` is the weighted threat level at the position; ``distance`` is the
    distance to the goal in metres.  ``reach`` is how far a simulated unit
    moves along it: ``step``, or less on the final approach, which ends on the
    goal; a tracking stepper's unit on a route may go on to the pursuit point
    (``tracking``), which is farther.  ``to`` (``to_x, to_y``) is where one
    planner step ends (``steprule.judge``): a simulating driver moves there.
    A terminal advice has ``reach`` infinite and ``to`` not a number.
    """

    status: StepStatus
    dx: float
    dy: float
    level: float
    distance: float
    reason: str = ""
    deliberating: bool = False
    reach: float = math.inf
    to_x: float = math.nan  # two floats, not a tuple: no container for the collector per advice
    to_y: float = math.nan
    route: Route = Route.NONE  # what the route the unit follows is (``tracking``)

    @property
    def to(self) -> tuple[float, float]:
        """Where the step along this advice ends."""
        return (self.to_x, self.to_y)


class Need(NamedTuple):
    """Deliberation a deferring stepper asks for: ``foresee`` (look-ahead) or ``escape`` (a trap)."""

    kind: str
    x: float
    y: float
    reason: str = ""
