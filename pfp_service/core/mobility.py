"""Mobility classes: how steep a unit can climb, how tall it stands, how fast it goes on a slope.

One registry, ``CLASSES``: a scenario's ``unit:`` block names a class and may
override any field (``Mobility.merged``).  Speed on a slope ``g`` (rise over
run along the path, signed: positive uphill):

- ``foot``: Tobler's hiking function, scaled to the class's flat speed:
  ``v = speed_mps * exp(-3.5 (|g + 0.05| - 0.05))`` (Tobler 1993: 6 km/h at
  its fastest, 5 % downhill; 5.04 km/h = 1.4 m/s on the flat).
- ``wheeled`` and ``tracked``: a vehicle's speed falls linearly with the
  grade, uphill to ``VEHICLE_UPHILL_AT_LIMIT`` of its flat speed at its
  slope limit, downhill (engine braking) to ``VEHICLE_DOWNHILL_AT_LIMIT``;
  steeper than its limit it does not move (speed 0).

The defaults: a soldier (1.8 m, 30 degrees, 1.4 m/s); a wheeled vehicle
(2.5 m, 17 degrees, about a 30 % grade, 10 m/s off road); a tracked vehicle
(2.5 m, 31 degrees, the 60 % grade a main battle tank's specification
states, 8 m/s off road).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

__all__ = [
    "CLASSES",
    "CLASS_LIMITS",
    "HEIGHT_STEP_M",
    "Mobility",
    "MobilityClass",
    "planned_height",
    "planned_limit",
    "speed_mps",
]

MobilityClass = Literal["foot", "wheeled", "tracked"]

VEHICLE_UPHILL_AT_LIMIT = 0.3
VEHICLE_DOWNHILL_AT_LIMIT = 0.6


@dataclass(frozen=True)
class Mobility:
    """A unit's ground limits: its class, steepest slope, height (what a threat must see) and flat speed."""

    kind: MobilityClass
    max_slope_deg: float
    height_m: float
    speed_mps: float

    def merged(
        self,
        max_slope_deg: float | None = None,
        height_m: float | None = None,
        speed_mps: float | None = None,
    ) -> Mobility:
        """This class with the fields given overridden."""
        return replace(
            self,
            max_slope_deg=self.max_slope_deg if max_slope_deg is None else float(max_slope_deg),
            height_m=self.height_m if height_m is None else float(height_m),
            speed_mps=self.speed_mps if speed_mps is None else float(speed_mps),
        )


CLASSES: dict[str, Mobility] = {
    "foot": Mobility("foot", max_slope_deg=30.0, height_m=1.8, speed_mps=1.4),
    "wheeled": Mobility("wheeled", max_slope_deg=17.0, height_m=2.5, speed_mps=10.0),
    "tracked": Mobility("tracked", max_slope_deg=31.0, height_m=2.5, speed_mps=8.0),
}
# The whole-degree slope limits the live planner always holds barriers for: the classes' own.  A
# barrier set over a 1,000 x 1,000-cell DEM takes 0.3-2.2 s to build (docs/terrain.md), too long for
# the live loop, so these are built when the terrain loads; an override's is built off the loop when
# a unit wants it, and the unit planned at one of these meanwhile (``world.slopes``).
CLASS_LIMITS: tuple[int, ...] = tuple(sorted({round(c.max_slope_deg) for c in CLASSES.values()}))


def planned_limit(max_slope_deg: float) -> int | None:
    """The class limit a unit that climbs ``max_slope_deg`` is planned at while its own barriers are
    not held: the steepest of ``CLASS_LIMITS`` not above it, the safe side (``None``: below every one of
    them)."""
    fit = [lim for lim in CLASS_LIMITS if lim <= round(max_slope_deg)]
    return fit[-1] if fit else None


# A height override is seen by the threats at the next multiple of this up: each height in use costs the
# world a re-heighted copy of the threats' field (docs/terrain.md), so near heights share one, on the
# safe side (a taller unit is seen more).  The classes' own heights are seen as they are.
HEIGHT_STEP_M = 0.25
_CLASS_HEIGHTS = frozenset(c.height_m for c in CLASSES.values())


def planned_height(height_m: float) -> float:
    """The height a unit ``height_m`` tall is seen at by the threats: a class's own height as it is, any other
    at the next multiple of ``HEIGHT_STEP_M`` up (the safe side)."""
    if height_m in _CLASS_HEIGHTS:
        return height_m
    return math.ceil(round(height_m / HEIGHT_STEP_M, 9)) * HEIGHT_STEP_M


def speed_mps(unit: Mobility, grade: np.ndarray) -> np.ndarray:
    """Speed over ground on ``grade`` (rise over run, positive uphill), per the class's model; 0 past its limit."""
    g = np.asarray(grade, dtype=float)
    limit = math.tan(math.radians(unit.max_slope_deg))
    if unit.kind == "foot":
        v = unit.speed_mps * np.exp(-3.5 * (np.abs(g + 0.05) - 0.05))
    else:
        share = np.minimum(np.abs(g) / limit, 1.0)
        loss = np.where(g > 0, 1.0 - VEHICLE_UPHILL_AT_LIMIT, 1.0 - VEHICLE_DOWNHILL_AT_LIMIT)
        v = unit.speed_mps * (1.0 - loss * share)
    return np.where(np.abs(g) > limit, 0.0, v)
