"""Path-quality metrics: length, exposure, peak threat and clearance.

Exposure is the line integral of the weighted threat level along the path,
``sum_i integral over segment i of sum_j w_j t_j ds``, by Simpson's rule per
segment.  Each segment is judged under the field that was in force when it was
walked, so a pop-up threat counts only from its appearance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pfp_service.core.threat import ThreatField

__all__ = ["Epoch", "PathMetrics", "measure", "segment_clearance"]


@dataclass(frozen=True, slots=True)
class Epoch:
    """Segments ``[first, last)`` of a path were walked under ``field``."""

    first: int
    last: int
    field: ThreatField


@dataclass(frozen=True, slots=True)
class PathMetrics:
    length: float
    exposure: float
    peak_threat: float
    min_clearance: float  # inf when no threat was ever in force


def segment_clearance(path: np.ndarray, positions: np.ndarray) -> float:
    """Smallest distance from any segment of ``path`` to any of ``positions``."""
    if len(positions) == 0:
        return math.inf
    if len(path) == 1:
        d = np.hypot(positions[:, 0] - path[0, 0], positions[:, 1] - path[0, 1])
        return float(d.min())
    a = path[:-1, None, :]
    ab = (path[1:] - path[:-1])[:, None, :]
    ap = positions[None, :, :] - a
    denom = np.einsum("ijk,ijk->ij", ab, ab)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(denom > 0, np.einsum("ijk,ijk->ij", ap, ab) / denom, 0.0)
    t = np.clip(t, 0.0, 1.0)
    closest = a + t[..., None] * ab
    d = np.hypot(positions[None, :, 0] - closest[..., 0], positions[None, :, 1] - closest[..., 1])
    return float(d.min())


def measure(path: np.ndarray, epochs: list[Epoch]) -> PathMetrics:
    """Metrics of ``path`` (``(K+1, 2)``) walked under ``epochs``.

    A path of a single point has length and exposure 0, and its peak threat is
    the level where it stands.
    """
    seg = np.diff(path, axis=0)
    seglen = np.hypot(seg[:, 0], seg[:, 1])
    exposure = 0.0
    peak = 0.0
    clearance = math.inf
    for ep in epochs:
        if len(ep.field) == 0:
            continue
        if ep.last <= ep.first:
            # no segment walked under this field: only the point where it stood
            pt = path[min(ep.first, len(path) - 1)][None, :]
            peak = max(peak, float(ep.field.level(pt)[0]))
            clearance = min(clearance, segment_clearance(pt, ep.field.positions))
            continue
        a = path[ep.first : ep.last]
        b = path[ep.first + 1 : ep.last + 1]
        pts = np.concatenate([a, 0.5 * (a + b), b])
        lv = ep.field.level(pts)
        n = len(a)
        fa, fm, fb = lv[:n], lv[n : 2 * n], lv[2 * n :]
        exposure += float(np.sum(seglen[ep.first : ep.last] * (fa + 4.0 * fm + fb)) / 6.0)
        peak = max(peak, float(lv.max()))
        clearance = min(clearance, segment_clearance(path[ep.first : ep.last + 1], ep.field.positions))
    return PathMetrics(float(seglen.sum()), exposure, peak, clearance)
