"""What the map draws of a threat, from its shape (``core.shapes``): outlines, marks and a description.

The geometry is the planner's own: the peak is ``Threat.mode`` and the ring is
the shape's ``outline`` (the skew-normal's bisects along a fan of rays from the
peak using the cores' level ratio; the area's is a circle).  The page draws
the polygons and lines it is given and knows no shape's parameters.
The zone drawn on the map is ``ZONE_FRACTION`` of
the peak; the core is the planner's own ``CORE_FRACTION`` (half the peak), so
what the map calls a core is exactly what no escape may enter.  Numbers in,
numbers out.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import msgspec

from pfp_service.core import shapes
from pfp_service.core.cores import CORE_FRACTION
from pfp_service.core.threat import Threat
from pfp_service.wire import ThreatUpdate
from pfp_service.world import translate

__all__ = [
    "CORE_FRACTION",
    "ZONE_FRACTION",
    "ThreatView",
    "marks",
    "outline",
    "peak_point",
    "threat_view",
]

ZONE_FRACTION = 0.1
_RAYS = 48


def peak_point(threat: Threat) -> tuple[float, float]:
    """Where the threat's density is highest, in metres (the enemy position for an unskewed threat)."""
    return threat.mode()


def outline(update: ThreatUpdate, fraction: float, rays: int = _RAYS) -> list[tuple[float, float]]:
    """The polygon ``t(x) = fraction * max t`` of one threat, counter-clockwise from east, in metres.

    Args:
        update: the threat as put on the wire (its weight does not matter: the ratio is per threat).
        fraction: of the peak, in ``(0, 1)``.
        rays: vertices of the polygon.

    Returns:
        ``rays`` points, each rounded to the millimetre.

    Raises:
        ValueError: ``fraction`` outside ``(0, 1)``, or a threat its shape refuses.
    """
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"fraction must be in (0, 1), got {fraction!r}")
    # the ratio to the peak is per threat, so weight 1 stands for any weight (even 0, which has no core)
    threat = dataclasses.replace(translate.threat(update, ""), weight=1.0)
    return shapes.get(update.shape).outline(threat, fraction, rays)


def marks(update: ThreatUpdate) -> list[list[tuple[float, float]]]:
    """The lines the shape draws beside its outline (the skew-normal's facing arrow), in metres."""
    return shapes.get(update.shape).marks(update.position, translate.shape_params(update))


@dataclass(slots=True)
class ThreatView:
    """One threat the map holds: the update as put, and what the page draws of it."""

    id: str
    update: ThreatUpdate
    put_at: float
    expires_at: float | None
    zone: list[tuple[float, float]]
    core: list[tuple[float, float]]
    peak: tuple[float, float]
    marks: list[list[tuple[float, float]]]
    rows: list[tuple[str, str]]

    def view(self) -> dict[str, Any]:
        """The threat as the page draws it: polygons, lines and rows from its shape, and the update to re-put."""
        u = self.update
        return {
            "id": self.id,
            "position": u.position,
            "shape": u.shape,
            "update": msgspec.to_builtins(u),
            "weight": u.weight,
            "ttl_s": u.ttl_s,
            "put_at": self.put_at,
            "expires_at": self.expires_at,
            "zone": self.zone,
            "core": self.core,
            "peak": self.peak,
            "marks": self.marks,
            "rows": self.rows,
        }


def threat_view(threat_id: str, update: ThreatUpdate, now: float, ttl_left_s: float | None) -> ThreatView:
    return ThreatView(
        threat_id,
        update,
        now,
        None if ttl_left_s is None else now + ttl_left_s,
        outline(update, ZONE_FRACTION),
        outline(update, CORE_FRACTION) if update.weight > 0 else [],
        peak_point(translate.threat(update, threat_id)),
        marks(update),
        translate.describe(update),
    )
