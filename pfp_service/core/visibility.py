"""Threats that see: each threat's window of lowest visible heights, packed into its own row.

A threat over terrain contributes ``w t(x) v(x)``, where ``v`` is how well it
sees a unit at ``x``: ``v = sigmoid((height_m - L(x)) / softness_m)``, ``L`` the
lowest height above the ground at which it sees a target there (what
``gdal_viewshed -om GROUND`` writes), interpolated bilinearly, and
``height_m`` the unit's.  ``L`` comes from the terrain (``terrain.threat_sight``
computes it); the core only carries it: a ``Window`` per threat, appended to
the threat's packed row (``kernels.VIS_DATA``), so every kernel masks the
same way (``kernels.sight``).

A ``Sight`` is what a field asks for a threat's window: a callable, given the
threat and the box of its reach, that returns its ``Window`` or ``None``
(no terrain under it: it sees everywhere).  Rows of different widths are
padded with zeros to the widest: a window's own size is in its row.

A unit's height.  ``L`` does not depend on the target, so one window serves
every height: ``Window.at`` is the same ``low_m`` (shared, not copied) under
another ``height_m`` and ``softness_m``; ``AtHeight`` is a sight whose
windows are its inner sight's at one height; ``at_height`` re-heights a
packed field's rows, no window swept again.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from pfp_service.core import kernels

__all__ = [
    "MIN_HEIGHT_M",
    "REACH_FLOOR",
    "AtHeight",
    "Sight",
    "Window",
    "at_height",
    "concat",
    "finest_cell",
    "reach_box",
    "softness_for",
    "stack_rows",
    "unmasked",
    "widen",
]

# A threat's window covers where its own term is at least this share of its
# peak: beyond, the mask multiplies almost nothing, and the window is clamped.
REACH_FLOOR = 1e-9
# the least height a softness is made for: a unit flat on the ground still gets a sigmoid of finite slope
MIN_HEIGHT_M = 0.06


def softness_for(height_m: float) -> float:
    """The sigmoid's width for a unit ``height_m`` tall: a sixth of it (of ``MIN_HEIGHT_M`` at least).

    A unit in the open (lowest visible height 0) is then seen at
    ``sigmoid(6) = 99.75 %``, one whose ground hides it to half its height at
    50 %, and one hidden by its full height at 0.25 %.
    """
    return max(height_m, MIN_HEIGHT_M) / 6.0


@dataclass(frozen=True, eq=False)
class Window:
    """Lowest visible heights ``low_m[k, i]`` at ``(x0_m + i cell_m, y0_m + k cell_m)``, at least 2 x 2.

    ``height_m`` is the unit's height (the target's), ``softness_m`` the
    sigmoid's width: ``v`` goes from 0.27 to 0.73 over two of it.
    """

    x0_m: float
    y0_m: float
    cell_m: float
    low_m: np.ndarray
    height_m: float
    softness_m: float

    def __post_init__(self) -> None:
        if self.low_m.ndim != 2 or min(self.low_m.shape) < 2:
            raise ValueError("a visibility window needs at least 2 x 2 heights")
        if not (self.cell_m > 0 and self.softness_m > 0):
            raise ValueError("a visibility window's cell and softness must be positive")

    def max_dv(self) -> float:
        """A bound on ``|grad v|`` (1/m): ``max |grad L| / (4 softness)``, the logistic's slope at most 1/4."""
        low = self.low_m
        gx = np.abs(np.diff(low, axis=1)).max() if low.shape[1] > 1 else 0.0
        gy = np.abs(np.diff(low, axis=0)).max() if low.shape[0] > 1 else 0.0
        return float(math.hypot(gx, gy) / self.cell_m / (4.0 * self.softness_m))

    def at(self, height_m: float) -> Window:
        """This window for a unit ``height_m`` tall: the same ``low_m`` array (not copied), the sigmoid's
        height and width that unit's (``softness_for``)."""
        if height_m == self.height_m:
            return self
        return replace(self, height_m=float(height_m), softness_m=softness_for(height_m))


Sight = Callable[[object, tuple[float, float, float, float]], "Window | None"]


@dataclass(frozen=True)
class AtHeight:
    """``sight``'s windows for a unit ``height_m`` tall (``Window.at``): no window swept again.

    Equal, and hashed alike, for the same sight and height, so a worker's
    fields (``node.workerproc.world_field``) are shared by every unit of one
    height; it pickles as its sight does (a live terrain by name).
    """

    sight: Sight
    height_m: float

    def __call__(self, threat: object, box: tuple[float, float, float, float]) -> Window | None:
        got = self.sight(threat, box)
        return got.at(self.height_m) if got is not None else None


def at_height(packed: np.ndarray, height_m: float) -> np.ndarray:
    """A copy of ``packed`` whose masked rows see a unit ``height_m`` tall (their windows' heights kept).

    The bound on ``|grad v|`` (``VIS_DV``, ``Window.max_dv``) is inversely
    proportional to the softness, so it is scaled, not computed again.
    """
    out = packed.copy()
    if not len(out) or out.shape[1] <= kernels.VIS_DV:
        return out
    masked = out[:, kernels.VIS_NX] > 0
    soft = softness_for(height_m)
    out[masked, kernels.VIS_DV] *= out[masked, kernels.VIS_SOFT] / soft
    out[masked, kernels.VIS_HEIGHT] = float(height_m)
    out[masked, kernels.VIS_SOFT] = soft
    return out


def reach_box(row: np.ndarray, floor: float = REACH_FLOOR) -> tuple[float, float, float, float]:
    """``(x0, y0, x1, y1)``: the box outside which threat ``row``'s term is below ``floor`` of its peak.

    The threat's own, whatever else is in the field, so a window computed once
    serves every field the threat is in.
    """
    qmax = min(2.0 * math.log(1.0 / floor), kernels.Q_CUTOFF)
    p00, p01, p11 = row[kernels.P00], row[kernels.P01], row[kernels.P11]
    det = p00 * p11 - p01 * p01
    ex = math.sqrt(qmax * p11 / det)
    ey = math.sqrt(qmax * p00 / det)
    cx, cy = float(row[kernels.XI_X]), float(row[kernels.XI_Y])
    return cx - ex, cy - ey, cx + ex, cy + ey


def widen(packed: np.ndarray, windows: Sequence[Window | None]) -> np.ndarray:
    """``packed`` (one row a threat) with each threat's window written into its row; the rows padded."""
    width = kernels.VIS_DATA + max((w.low_m.size for w in windows if w is not None), default=0)
    out = np.zeros((packed.shape[0], width))
    out[:, : kernels.VIS_DATA] = packed[:, : kernels.VIS_DATA]
    for j, w in enumerate(windows):
        if w is None:
            continue
        ny, nx = w.low_m.shape
        out[j, kernels.VIS_NX] = nx
        out[j, kernels.VIS_NY] = ny
        out[j, kernels.VIS_X0] = w.x0_m
        out[j, kernels.VIS_Y0] = w.y0_m
        out[j, kernels.VIS_CELL] = w.cell_m
        out[j, kernels.VIS_HEIGHT] = w.height_m
        out[j, kernels.VIS_SOFT] = w.softness_m
        out[j, kernels.VIS_DV] = w.max_dv()
        # unknown ground hides nothing (docs/terrain.md): a NaN height is seen from the ground up
        out[j, kernels.VIS_DATA : kernels.VIS_DATA + ny * nx] = np.nan_to_num(w.low_m, nan=0.0).ravel()
    return out


def stack_rows(rows: Sequence[np.ndarray]) -> np.ndarray:
    """Packed rows of any widths as one array, padded with zeros to the widest."""
    if rows and all(len(r) == len(rows[0]) for r in rows):
        return np.array(rows, dtype=np.float64)
    width = max((len(r) for r in rows), default=len(kernels.PACKED_COLUMNS))
    out = np.zeros((len(rows), width))
    for j, r in enumerate(rows):
        out[j, : len(r)] = r
    return out


def concat(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Two packed arrays, one after the other, the narrower padded with zeros."""
    if a.shape[1] == b.shape[1]:
        return np.concatenate([a, b])
    width = max(a.shape[1], b.shape[1])
    out = np.zeros((a.shape[0] + b.shape[0], width))
    out[: a.shape[0], : a.shape[1]] = a
    out[a.shape[0] :, : b.shape[1]] = b
    return out


def finest_cell(packed: np.ndarray) -> float:
    """The finest window cell among ``packed``'s threats (metres); ``inf`` when none is masked.

    A masked level changes over a window cell (its lowest visible heights
    step from hidden to seen there), where an unmasked one changes over a
    threat's spread: whatever samples a masked field along a line (a route
    search's edges, a shortcut's candidates) must sample at this scale.
    """
    if not len(packed) or packed.shape[1] <= kernels.VIS_CELL:
        return math.inf
    masked = packed[:, kernels.VIS_NX] > 0
    return float(packed[masked, kernels.VIS_CELL].min()) if masked.any() else math.inf


def unmasked(packed: np.ndarray) -> np.ndarray:
    """A copy of ``packed`` without the windows: the threats as if they saw everywhere."""
    out = packed[:, : kernels.VIS_DATA].copy()
    out[:, kernels.VIS_NX] = 0.0
    return out
