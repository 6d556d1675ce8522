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

With ``avoid_cores`` (``pfp plan --planner optimal --avoid-cores``) the threat
cores are a hard constraint: the graph leaves out the search cores
(``cores.SEARCH_FRACTION``), the cell shrinks to at most 3.5 narrowest standard
deviations (up to 4x ``cells``) so no core slips between edge probes, and a
goal that no core-free route reaches is ``trapped``, not ``reached``.  The
grid's levels and cores are rasterised per threat box (``kernels.raster_level``,
``Cores.raster``), so a thousand small threats cost about what a few do.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from pfp_service.core.cores import SEARCH_FRACTION, Cores
from pfp_service.core.grid import GridGraph
from pfp_service.core.metrics import LAMBDA, Epoch, measure
from pfp_service.core.options import DEFAULT_CELLS
from pfp_service.core.plan import PlanResult, PlanStatus, Scheduled, UsedParams
from pfp_service.core.polylines import resample, shortcut
from pfp_service.core.stepper import Bounds
from pfp_service.core.threat import Intensity, ThreatField
from pfp_service.core.visibility import Sight
from pfp_service.core.zones import ZoneSet

__all__ = ["DEFAULT_CELLS", "OptimalPath", "OptimalSolver", "plan_optimal"]


@dataclass(frozen=True, slots=True)
class OptimalPath:
    """A path from the solver; empty ``path`` when no route exists."""

    path: np.ndarray
    length: float
    exposure: float
    cost: float


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
        if avoid_cores:
            self.cores: Cores | None = Cores.of(field, SEARCH_FRACTION)
        elif field.zones:  # keep-out zones are kept out always; threat cores only when asked
            self.cores = Cores.of(ThreatField((), field.intensity, field.zones))
        else:
            self.cores = None
        if field.zones:
            box = _round_zones(field.zones, box, 0.02 * math.hypot(goal[0] - start[0], goal[1] - start[1]))
        (x0, y0), (x1, y1) = box
        span = max(x1 - x0, y1 - y0)
        cell_m = span / cells if span > 0 else 1.0
        if self.cores is not None and cell_m > 3.5 * self.cores.min_spread_m:
            cell_m = max(3.5 * self.cores.min_spread_m, span / (4 * cells))
        self.graph = GridGraph(field, box, cells, 16, self.cores, cell_m)
        self._src = self.graph.nearest(*self.start)
        self._dst = self.graph.nearest(*self.goal)

    def solve(self, lam: float) -> OptimalPath:
        """The path minimising ``length + lam * exposure`` (empty if the goal is cut off)."""
        route = self.graph.route(self._src, self._dst, lam)
        if not len(route.points):
            return OptimalPath(np.zeros((0, 2)), math.inf, math.inf, math.inf)
        pts = np.concatenate([[self.start], route.points, [self.goal]])
        keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)])
        pts = shortcut(self.field, pts[keep], lam, self.cores)
        pts = resample(pts, self.graph.cell_m / 2.0)
        m = measure(pts, [Epoch(0, len(pts) - 1, self.field)])
        return OptimalPath(pts, m.length, m.exposure, m.length + lam * m.exposure)


def _round_zones(zones: ZoneSet, box: Bounds, room: float) -> Bounds:
    """``box`` grown to hold every keep-out zone it meets, with ``room`` to go round (twice: zones in a chain)."""
    (x0, y0), (x1, y1) = box
    b = zones.boxes
    for _ in range(2):
        meet = (b[:, 0] <= x1) & (b[:, 2] >= x0) & (b[:, 1] <= y1) & (b[:, 3] >= y0)
        if not meet.any():
            break
        x0 = min(x0, float(b[meet, 0].min()) - room)
        y0 = min(y0, float(b[meet, 1].min()) - room)
        x1 = max(x1, float(b[meet, 2].max()) + room)
        y1 = max(y1, float(b[meet, 3].max()) + room)
    return (x0, y0), (x1, y1)


def plan_optimal(
    start: tuple[float, float],
    goal: tuple[float, float],
    schedule: Sequence[Scheduled] = (),
    lam: float = LAMBDA,
    intensity: Intensity = "peak",
    bounds: Bounds | None = None,
    cells: int = DEFAULT_CELLS,
    clock: Callable[[], float] | None = None,
    avoid_cores: bool = False,
    zones: ZoneSet | None = None,
    sight: Sight | None = None,
) -> PlanResult:
    """``pfp plan --planner optimal``: the path minimising ``length + lam * exposure``.

    Args:
        avoid_cores: never enter a threat core (``--avoid-cores``).
        zones: keep-out zones; the path never enters one (with or without ``avoid_cores``).
        sight: threats masked by line of sight (``core.visibility``), as ``plan``'s.

    Returns:
        A ``PlanResult`` (``planner="optimal"``): ``reached`` with the path;
        ``trapped`` when ``avoid_cores`` and no core-free route exists; or
        ``invalid`` with the reason when the grid holds no route.
    """
    t0 = clock() if clock else 0.0
    field = ThreatField([s.threat for s in schedule], intensity, zones, sight)
    why = ""
    if field.zones:
        for what, (x, y) in (("goal", goal), ("start", start)):
            inside = field.zones.zone_at(float(x), float(y))
            if inside:
                why = f"the {what} lies in zone {inside}"
    found = OptimalPath(np.zeros((0, 2)), math.inf, math.inf, math.inf)
    cell_m = 0.0
    if not why:
        solver = OptimalSolver(field, start, goal, bounds, cells, avoid_cores)
        found = solver.solve(lam)
        cell_m = solver.graph.cell_m
        hit = solver.cores.first_hit(found.path) if solver.cores is not None and len(found.path) else ""
        if hit:  # the start or goal's link to the grid clips one: no honest path on this grid
            why = f"the route on the {cell_m:.4g} m grid clips {Cores.region(hit)}: a finer grid is needed"
            found = OptimalPath(np.zeros((0, 2)), math.inf, math.inf, math.inf)
    used = UsedParams(None, cell_m, None, None, intensity, "none")  # no descent parameters
    ms = ((clock() - t0) * 1e3) if clock else 0.0
    if not len(found.path):
        cell = f"{cell_m:.4g} m grid"
        what = "the threat cores and zones" if avoid_cores and field.zones else "the threat cores"
        if not avoid_cores and field.zones:
            what = "the zones"
        return PlanResult(
            status=PlanStatus.TRAPPED if avoid_cores or field.zones else PlanStatus.INVALID,
            reason=why
            or (
                f"no route from start to goal avoids {what} ({cell})"
                if avoid_cores or field.zones
                else "no route on the grid from start to goal"
            ),
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
        reason=f"minimum of length + {lam:g} * exposure on a {cell_m:.4g} m 16-connected grid"
        + (", avoiding every threat core" if avoid_cores else "")
        + (", keeping out of every zone" if field.zones else ""),
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
        min_zone_clearance=m.min_zone_clearance if math.isfinite(m.min_zone_clearance) else None,
    )
