"""Outlines of a threat for the map: the polygon where its own level is a given fraction of its peak.

A threat's density (a skew-normal: a Gaussian times a normal CDF) is
log-concave, so every region ``t(x) >= f * max t`` is convex and contains the
peak.  Each ray from the peak therefore crosses the outline exactly once, and
the outline is found by bisection along a fan of rays, vectorised over them.
The zone drawn on the map is ``ZONE_FRACTION`` of the peak; the core is the
planner's own ``CORE_FRACTION`` (half the peak), so what the map calls a core
is exactly what no escape may enter.  Numbers in, numbers out.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from pfp_service.core.cores import CORE_FRACTION
from pfp_service.core.threat import Threat, skew_normal_mode
from pfp_service.wire import ThreatUpdate

__all__ = ["CORE_FRACTION", "ZONE_FRACTION", "outline", "peak_point"]

ZONE_FRACTION = 0.1
_RAYS = 48
_BISECTIONS = 40


def peak_point(threat: Threat) -> tuple[float, float]:
    """Where the threat's density is highest, in metres (the enemy position for an unskewed threat)."""
    (o00, o01), (_, o11) = threat.omega
    ax, ay = threat.shape()
    oax, oay = o00 * ax + o01 * ay, o01 * ax + o11 * ay
    q = math.sqrt(max(ax * oax + ay * oay, 0.0))
    if q == 0.0:
        return threat.xi
    v = skew_normal_mode(q)
    return threat.xi[0] + oax * v / q, threat.xi[1] + oay * v / q


def _ratio(threat: Threat, points: np.ndarray, peak: float) -> np.ndarray:
    p00, p01, p11 = threat.precision()
    ax, ay = threat.shape()
    zx = points[..., 0] - threat.xi[0]
    zy = points[..., 1] - threat.xi[1]
    quad = p00 * zx * zx + 2.0 * p01 * zx * zy + p11 * zy * zy
    density = threat.density_scale() * np.exp(-0.5 * quad) * ndtr(ax * zx + ay * zy)
    return np.asarray(density / peak)


def outline(update: ThreatUpdate, fraction: float, rays: int = _RAYS) -> list[tuple[float, float]]:
    """The polygon ``t(x) = fraction * max t`` of one threat, counter-clockwise, in metres.

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
    threat = update.to_threat("")
    peak = threat.peak_density()
    cx, cy = peak_point(threat)
    angles = np.linspace(0.0, 2.0 * math.pi, rays, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    # At Mahalanobis radius m the Gaussian factor alone is exp(-m^2/2) of its value at the
    # centre; the skew factor only lowers the level further out, so m with exp(-m^2/2) below
    # fraction / 2, times the widest spread, past the peak's own offset, is outside.
    widest = max(update.sigma_range, update.sigma_lateral)
    offset = math.hypot(cx - threat.xi[0], cy - threat.xi[1])
    far = offset + widest * math.sqrt(2.0 * math.log(2.0 / fraction)) * 1.5 + 1e-9
    lo = np.zeros(rays)
    hi = np.full(rays, far)
    centre = np.array([cx, cy])
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        inside = _ratio(threat, centre + dirs * mid[:, None], peak) >= fraction
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    pts = centre + dirs * (0.5 * (lo + hi))[:, None]
    return [(round(float(x), 3), round(float(y), 3)) for x, y in pts]
