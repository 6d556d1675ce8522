"""Outlines of a threat for the map: the polygon where its own level is a given fraction of its peak.

The geometry is the planner's own: the peak is ``Threat.mode`` and the ring is
``geojson.zone_ring``, which bisects along a fan of rays from the peak using
the cores' level ratio (a threat's density is log-concave, so each ray
crosses the outline once).  The zone drawn on the map is ``ZONE_FRACTION`` of
the peak; the core is the planner's own ``CORE_FRACTION`` (half the peak), so
what the map calls a core is exactly what no escape may enter.  Numbers in,
numbers out.
"""

from __future__ import annotations

import dataclasses

from pfp_service.core.cores import CORE_FRACTION
from pfp_service.core.threat import Threat
from pfp_service.geojson import zone_ring
from pfp_service.wire import ThreatUpdate
from pfp_service.world import translate

__all__ = ["CORE_FRACTION", "ZONE_FRACTION", "outline", "peak_point"]

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
        ValueError: ``fraction`` outside ``(0, 1)``.
    """
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"fraction must be in (0, 1), got {fraction!r}")
    # the ratio to the peak is per threat, so weight 1 stands for any weight (even 0, which has no core)
    threat = dataclasses.replace(translate.threat(update, ""), weight=1.0)
    ring = zone_ring(threat, fraction, rays)
    return [(round(float(x), 3), round(float(y), 3)) for x, y in ring]
