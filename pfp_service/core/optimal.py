"""The optimal reference planner: minimise ``J = length + lambda * exposure`` on a fine grid.

Method: Dijkstra (``scipy.sparse.csgraph``) on a 16-connected grid whose edges
cost their length plus ``lambda`` times their exposure (``grid.GridGraph``),
then a shortcut pass that replaces a run of grid edges by one straight segment
whenever that lowers ``J`` (it removes the grid's heading quantisation, up to
2.7 % of length with 16-connectivity).  The result is the same ``PlanResult``
as the potential-field planner's, measured by the same ``metrics.measure``.

It is an offline reference with full knowledge: every threat of the schedule
is in force from the start, whatever its ``appear_step``.  The grid covers the
mission bounds when given, else the start-goal box padded by half the
start-goal distance on every side.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from pfp_service.core.cores import Cores
from pfp_service.core.grid import GridGraph
from pfp_service.core.metrics import Epoch, measure
from pfp_service.core.plan import PlanResult, PlanStatus, Scheduled, UsedParams
from pfp_service.core.stepper import Bounds
from pfp_service.core.threat import Intensity, ThreatField

__all__ = ["DEFAULT_CELLS", "DEFAULT_LAMBDA", "OptimalPath", "OptimalSolver", "plan_optimal"]

DEFAULT_LAMBDA = 10.0
DEFAULT_CELLS = 300
_WINDOW = 48  # grid edges a shortcut may replace at once
_SAMPLES = 33  # Simpson points on a candidate shortcut


@dataclass(frozen=True, slots=True)
class OptimalPath:
    """A path from the solver; empty ``path`` when no route exists."""

    path: np.ndarray
    length: float
    exposure: float
    cost: float


def _segment_costs(field: ThreatField, a: np.ndarray, b: np.ndarray, lam: float) -> np.ndarray:
    """``J`` of straight segments ``a[k] -> b[k]`` by composite Simpson on ``_SAMPLES`` points."""
    t = np.linspace(0.0, 1.0, _SAMPLES)
    pts = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    lv = field.level(pts) if len(field) else np.zeros(pts.shape[:2])
    w = np.ones(_SAMPLES)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    length = np.hypot(*(b - a).T)
    return length + lam * length * (lv @ w) / (3.0 * (_SAMPLES - 1))


def _shortcut(field: ThreatField, pts: np.ndarray, lam: float, cores: Cores | None) -> np.ndarray:
    """Greedily replace runs of segments by straight ones that cost no more."""
    if len(pts) < 3:
        return pts
    seg = _segment_costs(field, pts[:-1], pts[1:], lam)
    prefix = np.concatenate([[0.0], np.cumsum(seg)])
    keep = [0]
    i = 0
    n = len(pts)
    while i < n - 1:
        js = np.arange(i + 2, min(n, i + _WINDOW + 1))
        best = i + 1
        if len(js):
            direct = _segment_costs(field, np.repeat(pts[i : i + 1], len(js), axis=0), pts[js], lam)
            ok = direct <= (prefix[js] - prefix[i]) * (1.0 + 1e-12)
            for j in js[ok][::-1]:
                if cores is None or not cores.first_hit(pts[[i, j]]):
                    best = int(j)
                    break
        keep.append(best)
        i = best
    return pts[keep]


def _resample(pts: np.ndarray, spacing: float) -> np.ndarray:
    seg = np.diff(pts, axis=0)
    k = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / spacing)).astype(np.int64)
    parts = [pts[:1]]
    for a, d, m in zip(pts[:-1], seg, k.tolist()):
        parts.append(a + (np.arange(1, m + 1)[:, None] / m) * d)
    return np.concatenate(parts)


class OptimalSolver:
    """One grid for one start-goal pair, solved for any ``lambda``.

    Args:
        field: every threat, in force.
        start, goal: metres.
        box: the area searched; ``None`` for the padded start-goal box.
        cells: grid resolution along the longer side.
        avoid_cores: leave threat cores out of the graph (a hard constraint).
    """

    def __init__(
        self,
        field: ThreatField,
        start: tuple[float, float],
        goal: tuple[float, float],
        box: Bounds | None = None,
        cells: int = DEFAULT_CELLS,
        avoid_cores: bool = False,
    ) -> None:
        self.field = field
        self.start = (float(start[0]), float(start[1]))
        self.goal = (float(goal[0]), float(goal[1]))
        if box is None:
            pad = 0.5 * math.hypot(goal[0] - start[0], goal[1] - start[1]) or 1.0
            box = (
                (min(start[0], goal[0]) - pad, min(start[1], goal[1]) - pad),
                (max(start[0], goal[0]) + pad, max(start[1], goal[1]) + pad),
            )
        self.cores = Cores(field) if avoid_cores else None
        self.graph = GridGraph(field, box, cells, 16, self.cores)
        self._src = self.graph.nearest(*self.start)
        self._dst = self.graph.nearest(*self.goal)

    def solve(self, lam: float) -> OptimalPath:
        """The path minimising ``length + lam * exposure`` (empty if the goal is cut off)."""
        route = self.graph.route(self._src, self._dst, lam)
        if not len(route.points):
            return OptimalPath(np.zeros((0, 2)), math.inf, math.inf, math.inf)
        pts = np.concatenate([[self.start], route.points, [self.goal]])
        keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)])
        pts = _shortcut(self.field, pts[keep], lam, self.cores)
        pts = _resample(pts, self.graph.cell_m / 2.0)
        m = measure(pts, [Epoch(0, len(pts) - 1, self.field)])
        return OptimalPath(pts, m.length, m.exposure, m.length + lam * m.exposure)


def plan_optimal(
    start: tuple[float, float],
    goal: tuple[float, float],
    schedule: Sequence[Scheduled] = (),
    lam: float = DEFAULT_LAMBDA,
    intensity: Intensity = "peak",
    bounds: Bounds | None = None,
    cells: int = DEFAULT_CELLS,
    clock: Callable[[], float] | None = None,
) -> PlanResult:
    """``pfp plan --planner optimal``: the path minimising ``length + lam * exposure``.

    Returns:
        A ``PlanResult`` (``planner="optimal"``): ``reached`` with the path, or
        ``invalid`` with the reason when the grid holds no route.
    """
    t0 = clock() if clock else 0.0
    field = ThreatField([s.threat for s in schedule], intensity)
    solver = OptimalSolver(field, start, goal, bounds, cells)
    found = solver.solve(lam)
    used = UsedParams(0.0, solver.graph.cell_m, 0, 0.0, intensity, "none")
    ms = ((clock() - t0) * 1e3) if clock else 0.0
    if not len(found.path):
        return PlanResult(
            status=PlanStatus.INVALID,
            reason="no route on the grid from start to goal",
            steps=0,
            length=0.0,
            exposure=0.0,
            peak_threat=0.0,
            min_clearance=None,
            final_distance=math.hypot(goal[0] - start[0], goal[1] - start[1]),
            path=[(float(start[0]), float(start[1]))],
            compute_ms=ms,
            params=used,
            planner="optimal",
            lam=lam,
        )
    m = measure(found.path, [Epoch(0, len(found.path) - 1, field)])
    return PlanResult(
        status=PlanStatus.REACHED,
        reason=f"minimum of length + {lam:g} * exposure on a {solver.graph.cell_m:.4g} m 16-connected grid",
        steps=len(found.path) - 1,
        length=m.length,
        exposure=m.exposure,
        peak_threat=m.peak_threat,
        min_clearance=m.min_clearance if math.isfinite(m.min_clearance) else None,
        final_distance=0.0,
        path=[(float(x), float(y)) for x, y in found.path],
        compute_ms=ms,
        params=used,
        planner="optimal",
        lam=lam,
    )
