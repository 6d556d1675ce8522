"""Threat cores: the regions no escape may drive through, and the test for them.

Definition (also in README.md, "Escape strategies"):  a point ``x`` lies in
the *core* of threat ``j`` when that threat's own level is at least half its
peak, ``t_j(x) >= CORE_FRACTION * max t_j`` with ``CORE_FRACTION = 0.5``: the
threat's half-maximum region.  For an unskewed threat that is the ellipse of
Mahalanobis radius ``sqrt(2 ln 2) ~= 1.18``, i.e. 1.18 ``sigma_range`` along
the facing and 1.18 ``sigma_lateral`` across it; skew pushes it forward.  The
test is per threat, so it does not depend on the weight or the intensity
scale, and overlapping tails of several threats never make a core.  A threat
of weight 0 has no core.

Paths are tested densely: segments are subdivided to a quarter of the
narrowest threat spread, so no core is stepped over between two points.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.threat import ThreatField

__all__ = ["CORE_FRACTION", "Cores"]

CORE_FRACTION = 0.5


@numba.njit(cache=True, nogil=True)
def _ratios(packed: np.ndarray, points: np.ndarray, out_ratio: np.ndarray, out_idx: np.ndarray) -> None:
    """Per point, the largest ``t_j / max t_j`` over threats and which threat gives it."""
    for i in range(points.shape[0]):
        best = 0.0
        arg = -1
        for j in range(packed.shape[0]):
            r = kernels.threat_term(packed, j, points[i, 0], points[i, 1], 0.0, False)[0]
            if r > best:
                best = r
                arg = j
        out_ratio[i] = best
        out_idx[i] = arg


@numba.njit(cache=True, nogil=True)
def _inside(packed: np.ndarray, points: np.ndarray, fraction: float, out: np.ndarray) -> None:
    """``out[i]``: some ``t_j / max t_j >= fraction`` at point i (exactly ``_ratios``' test, sooner)."""
    for i in range(points.shape[0]):
        hit = False
        for j in range(packed.shape[0]):
            if kernels.threat_term(packed, j, points[i, 0], points[i, 1], fraction, False)[0] >= fraction:
                hit = True
                break
        out[i] = hit


class Cores:
    """The cores of one threat field.

    Args:
        field: the threats in force.
        fraction: the share of each threat's peak that bounds its core.
    """

    __slots__ = ("fraction", "ids", "min_spread_m", "packed")

    def __init__(self, field: ThreatField, fraction: float = CORE_FRACTION) -> None:
        self.fraction = fraction
        keep = [j for j, t in enumerate(field.threats) if t.weight > 0]
        packed = field.packed[keep].copy() if keep else np.zeros((0, len(kernels.PACKED_COLUMNS)))
        for row, j in enumerate(keep):
            t = field.threats[j]
            packed[row, kernels.SCALE] = t.density_scale() / t.peak_density()  # level 1 at the mode
        self.packed = packed
        self.ids = [field.threats[j].id or f"#{j + 1}" for j in keep]
        self.min_spread_m = min((field.threats[j].min_sigma() for j in keep), default=math.inf)

    def ratio(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Largest normalised threat level ``t_j / max t_j`` at each point, and its threat index."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        ratio = np.zeros(len(pts))
        idx = np.full(len(pts), -1, dtype=np.int64)
        if len(self.packed) and len(pts):
            _ratios(self.packed, pts, ratio, idx)
        return ratio, idx

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask: which points lie in some threat's core."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(pts), dtype=np.bool_)
        if len(self.packed) and len(pts):
            _inside(self.packed, pts, self.fraction, out)
        return out

    def first_hit(self, path: np.ndarray) -> str:
        """The id of the first core the polyline ``path`` enters, or ``""`` if none."""
        pts = self.densify(np.asarray(path, dtype=np.float64).reshape(-1, 2))
        if not len(self.packed) or not len(pts):
            return ""
        ratio, idx = self.ratio(pts)
        hits = np.flatnonzero(ratio >= self.fraction)
        return self.ids[int(idx[hits[0]])] if len(hits) else ""

    def densify(self, path: np.ndarray) -> np.ndarray:
        """``path`` with every segment split to at most a quarter of the narrowest standard deviation."""
        if len(path) < 2 or not math.isfinite(self.min_spread_m):
            return path
        h = self.min_spread_m / 4.0
        seg = np.diff(path, axis=0)
        n = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / h)).astype(np.int64)
        if int(n.max()) == 1:
            return path
        which = np.repeat(np.arange(len(seg)), n)
        k = np.arange(len(which)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each segment
        t = (k / n[which])[:, None]
        return np.concatenate([path[:1], path[:-1][which] + t * seg[which]])
