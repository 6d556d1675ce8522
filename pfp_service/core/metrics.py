"""Path-quality metrics: length, exposure, peak threat, clearance and zone clearance.

Exposure is the line integral of the weighted threat level along the path,
``sum_i integral over segment i of sum_j w_j t_j ds``, by Simpson's rule per
segment.  Each segment is judged under the field that was in force when it was
walked, so a pop-up threat counts only from its appearance.

Where one number must rank paths, it is ``J = length + LAMBDA * exposure``
with the one ``LAMBDA`` below: the escapes' cost estimate, the ``global``
route's search, the optimal planner's default and the benchmark's ``J / J*``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from pfp_service.core.options import LAMBDA
from pfp_service.core.threat import ThreatField
from pfp_service.errors import DeadlinePassed

__all__ = ["LAMBDA", "Epoch", "PathMetrics", "exposure", "measure", "path_cost", "segment_clearance"]

MEASURE_CHUNK = 2048  # segments measured between two looks at the deadline


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
    # least signed distance to a keep-out zone (< 0: the path enters one); inf when no zone was in force
    min_zone_clearance: float = math.inf


@numba.njit(cache=True, nogil=True)
def _clearance(path: np.ndarray, positions: np.ndarray) -> float:
    best = math.inf
    for i in range(path.shape[0] - 1):
        ax, ay = path[i, 0], path[i, 1]
        bx, by = path[i + 1, 0] - ax, path[i + 1, 1] - ay
        denom = bx * bx + by * by
        for j in range(positions.shape[0]):
            px, py = positions[j, 0] - ax, positions[j, 1] - ay
            t = (px * bx + py * by) / denom if denom > 0 else 0.0
            t = min(max(t, 0.0), 1.0)
            d = math.hypot(px - t * bx, py - t * by)
            if d < best:
                best = d
    return best


def segment_clearance(path: np.ndarray, positions: np.ndarray) -> float:
    """Smallest distance from any segment of ``path`` to any of ``positions``."""
    if len(positions) == 0:
        return math.inf
    if len(path) == 1:
        d = np.hypot(positions[:, 0] - path[0, 0], positions[:, 1] - path[0, 1])
        return float(d.min())
    pts = np.ascontiguousarray(path, dtype=np.float64)
    return float(_clearance(pts, np.ascontiguousarray(positions, dtype=np.float64)))


def measure(path: np.ndarray, epochs: list[Epoch], deadline: Callable[[], bool] | None = None) -> PathMetrics:
    """Metrics of ``path`` (``(K+1, 2)``) walked under ``epochs``.

    A path of a single point has length and exposure 0, and its peak threat is
    the level where it stands.  ``deadline()`` is asked before each further
    ``MEASURE_CHUNK`` segments (a path shorter is measured whole): the metrics
    of a long path under thousands of threats take as long as walking it.

    Raises:
        DeadlinePassed: ``deadline()`` said so before every segment was measured.
    """
    seg = np.diff(path, axis=0)
    seglen = np.hypot(seg[:, 0], seg[:, 1])
    exposure = 0.0
    peak = 0.0
    clearance = math.inf
    zone_clearance = math.inf
    for ep in epochs:
        if ep.field.zones:  # exact per segment (``ZoneSet.clearance``)
            part = path[min(ep.first, len(path) - 1) : max(ep.last, ep.first) + 1]
            zone_clearance = min(zone_clearance, ep.field.zones.clearance(part))
    for ep in epochs:
        if len(ep.field) == 0:
            continue
        if ep.last <= ep.first:
            # no segment walked under this field: only the point where it stood
            pt = path[min(ep.first, len(path) - 1)][None, :]
            peak = max(peak, float(ep.field.level(pt)[0]))
            clearance = min(clearance, segment_clearance(pt, ep.field.positions))
            continue
        for first in range(ep.first, ep.last, MEASURE_CHUNK if deadline is not None else ep.last):
            if deadline is not None and first > ep.first and deadline():  # a short path is measured whole
                raise DeadlinePassed(f"the deadline passed measuring the path, at segment {first}")
            last = min(first + MEASURE_CHUNK, ep.last) if deadline is not None else ep.last
            a = path[first:last]
            b = path[first + 1 : last + 1]
            pts = np.concatenate([a, 0.5 * (a + b), b])
            lv = ep.field.level(pts)
            n = len(a)
            fa, fm, fb = lv[:n], lv[n : 2 * n], lv[2 * n :]
            exposure += float(np.sum(seglen[first:last] * (fa + 4.0 * fm + fb)) / 6.0)
            peak = max(peak, float(lv.max()))
            clearance = min(clearance, segment_clearance(path[first : last + 1], ep.field.positions))
    return PathMetrics(float(seglen.sum()), exposure, peak, clearance, zone_clearance)


def exposure(path: np.ndarray, field: ThreatField, culled: bool = False) -> float:
    """Simpson exposure of ``path`` (``(K+1, 2)``) walked under one ``field`` (``culled``: ``level_culled``)."""
    if len(path) < 2 or len(field) == 0:
        return 0.0
    a, b = path[:-1], path[1:]
    n = len(a)
    pts = np.concatenate([a, 0.5 * (a + b), b])
    lv = field.level_culled(pts) if culled else field.level(pts)
    seglen = np.hypot(*(b - a).T)
    return float(np.sum(seglen * (lv[:n] + 4.0 * lv[n : 2 * n] + lv[2 * n :])) / 6.0)


def path_cost(path: np.ndarray, field: ThreatField, lam: float = LAMBDA) -> float:
    """``J = length + lam * exposure`` of ``path`` walked under one ``field``, to rank ways.

    Exposure from ``ThreatField.level_culled`` (terms below ``LEVEL_FLOOR`` of
    the strongest peak left out): an estimate for choosing, not a reported metric.
    """
    pts = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    return float(np.hypot(*np.diff(pts, axis=0).T).sum()) + lam * exposure(pts, field, culled=True)
