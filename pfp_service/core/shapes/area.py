"""An area threat: an enemy somewhere in a circle, as a scout reports one, facing no way known.

The field is an isotropic Gaussian centred on the circle with the circle's
radius as its standard deviation (the skew-normal's form with no skew and
equal spreads, so it packs into the same kernel row).  Its outline has a
closed form: the level ``f`` of the peak lies at ``radius * sqrt(-2 ln f)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pfp_service.constraints import SIGMA_MIN_M
from pfp_service.core.shapes.base import Param, Point, Polyline, rounded
from pfp_service.errors import FINITE_LIMIT

if TYPE_CHECKING:  # the kernels compile on first use: describing a shape needs none
    from pfp_service.core.threat import Threat

__all__ = ["SHAPE", "Area"]


@dataclass(frozen=True, slots=True)
class Area:
    """The ``area`` shape (``ThreatShape``)."""

    name: str = "area"
    summary: str = "an enemy somewhere in a circle: an isotropic Gaussian, its radius the spread"
    params: tuple[Param, ...] = (
        Param("radius_m", SIGMA_MIN_M, FINITE_LIMIT, None, "the circle's radius, metres: the field's spread"),
    )

    def threat(self, position: Point, params: Mapping[str, float], weight: float, threat_id: str) -> Threat:
        from pfp_service.core.threat import Threat

        r2 = params["radius_m"] ** 2
        xy = (float(position[0]), float(position[1]))
        return Threat(
            xi=xy, omega=((r2, 0.0), (0.0, r2)), alpha=(0.0, 0.0), weight=float(weight), id=threat_id
        )

    def outline(self, threat: Threat, fraction: float, vertices: int) -> Polyline:
        if not 0.0 < fraction < 1.0:
            raise ValueError(f"level: must be strictly between 0 and 1, got {fraction}")
        r = math.sqrt(threat.omega[0][0] * -2.0 * math.log(fraction))
        x, y = threat.xi
        step = 2.0 * math.pi / vertices
        return rounded([(x + r * math.cos(k * step), y + r * math.sin(k * step)) for k in range(vertices)])

    def marks(self, position: Point, params: Mapping[str, float]) -> list[Polyline]:
        return []

    def describe(self, params: Mapping[str, float]) -> list[tuple[str, str]]:
        return [("radius", f"{params['radius_m']:g} m")]


SHAPE = Area()
