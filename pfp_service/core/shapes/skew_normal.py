"""The paper's skew-normal threat: an enemy facing one way, wide in front and steep behind.

Its parameters are the wire's first threat fields, which a message without a
``shape`` still gives at its top level: ``facing_deg``, ``sigma_range``,
``sigma_lateral`` and ``skew``.  The mapping to the raw form is
``Threat.from_facing``'s (``core.threat``'s docstring); its outline is the
level set traced by bisection, and it is drawn with an arrow along its facing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pfp_service.constraints import SIGMA_MIN_M, SIGMA_RATIO_MAX
from pfp_service.core.shapes.base import Param, Point, Polyline, ShapeError, level_ring, rounded
from pfp_service.errors import FINITE_LIMIT

if TYPE_CHECKING:  # the kernels compile on first use: describing a shape needs none
    from pfp_service.core.threat import Threat

__all__ = ["SHAPE", "SkewNormal"]

_ARROW_REACH = 1.5  # the arrow's length, in sigma_range: past the core, inside the drawn zone
_BARB = 0.3  # each barb's length, of the arrow's


@dataclass(frozen=True, slots=True)
class SkewNormal:
    """The ``skew_normal`` shape (``ThreatShape``)."""

    name: str = "skew_normal"
    summary: str = "an enemy facing one way: a skew-normal field, wide in front and steep behind"
    params: tuple[Param, ...] = (
        Param("facing_deg", -360.0, 360.0, 0.0, "the direction it faces, compass degrees"),
        Param("sigma_range", SIGMA_MIN_M, FINITE_LIMIT, None, "spread along the facing, metres"),
        Param("sigma_lateral", SIGMA_MIN_M, FINITE_LIMIT, None, "spread across the facing, metres"),
        Param("skew", 0.0, 1000.0, 0.0, "how far it reaches forward rather than back (0 = symmetric)"),
    )

    def threat(self, position: Point, params: Mapping[str, float], weight: float, threat_id: str) -> Threat:
        sr, sl = params["sigma_range"], params["sigma_lateral"]
        if max(sr, sl) > SIGMA_RATIO_MAX * min(sr, sl):
            raise ShapeError(
                f"params.sigma_lateral: sigma_range and sigma_lateral must be within a factor {SIGMA_RATIO_MAX:g}"
            )
        from pfp_service.core.threat import Threat

        return Threat.from_facing(position, params["facing_deg"], sr, sl, params["skew"], weight, threat_id)

    def outline(self, threat: Threat, fraction: float, vertices: int) -> Polyline:
        return rounded(level_ring(threat, fraction, vertices))

    def marks(self, position: Point, params: Mapping[str, float]) -> list[Polyline]:
        reach = _ARROW_REACH * params["sigma_range"]
        tip = _along(position, params["facing_deg"], reach)
        barbs = [_along(tip, params["facing_deg"] + s * 150.0, _BARB * reach) for s in (1, -1)]
        return [rounded([position, tip]), rounded([barbs[0], tip, barbs[1]])]

    def describe(self, params: Mapping[str, float]) -> list[tuple[str, str]]:
        return [
            ("facing", f"{params['facing_deg']:g}°"),
            ("σ range / lateral", f"{params['sigma_range']:g} / {params['sigma_lateral']:g} m"),
            ("skew", f"{params['skew']:g}"),
        ]


def _along(p: Point, bearing_deg: float, dist: float) -> Point:
    b = math.radians(bearing_deg)
    return p[0] + dist * math.sin(b), p[1] + dist * math.cos(b)


SHAPE = SkewNormal()
