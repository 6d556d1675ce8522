"""Terrain for ``pfp plan``: the DEM placed under a scenario, and a planned path measured over it.

``prepare`` reads the DEM's window under the scenario's area (its bounds, or
the box of its start, goal and threats with a margin), places it on the
scenario's plane (its ``origin``, or the DEM's centre when it has none) at
the DEM's own resolution, and gives what the planner takes: the threats'
``sight`` (``threat_sight.TerrainSight``, at the unit's height), the slope
barriers as keep-out zones (``barriers``), and bounds (the terrain's extent
when the scenario has none: beyond it the ground is unknown).

``profile`` measures a path over the ground: the elevation at each point,
the climb, the steepest ground crossed, the time at the unit's speed on each
slope (``core.mobility.speed_mps``), per threat the metres and seconds of the
path it sees, and the exposure the terrain-blind field would have priced.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pfp_service.core import kernels
from pfp_service.core.metrics import Epoch, measure
from pfp_service.core.mobility import Mobility, speed_mps
from pfp_service.core.plan import PlanResult, Scheduled, ThreatView
from pfp_service.core.threat import Intensity, ThreatField
from pfp_service.core.visibility import reach_box
from pfp_service.core.zones import Zone
from pfp_service.geo import Origin
from pfp_service.terrain.barriers import barrier_zones
from pfp_service.terrain.dem import info, read_dem
from pfp_service.terrain.grid import TerrainGrid, latlon_box, place
from pfp_service.terrain.sight import cell_metres
from pfp_service.terrain.threat_sight import TerrainSight

__all__ = ["MAX_POINTS", "PlanTerrain", "over_ground", "prepare", "profile"]

MAX_POINTS = 1_000_000  # terrain grid points at most: a coarser cell than the DEM's beyond
MARGIN_SHARE = 0.3  # of the start-goal distance, round the scenario's points
MARGIN_MIN_M = 500.0


@dataclass(frozen=True)
class PlanTerrain:
    """A DEM placed under one scenario, and what the planner takes from it."""

    path: str
    origin: Origin
    grid: TerrainGrid
    unit: Mobility
    sight: TerrainSight
    zones: list[Zone]
    bounds: tuple[tuple[float, float], tuple[float, float]]


def prepare(
    dem_path: str,
    origin: Origin | None,
    points: Sequence[tuple[float, float]],
    bounds: tuple[tuple[float, float], tuple[float, float]] | None,
    unit: Mobility,
) -> PlanTerrain:
    """The DEM under the scenario whose ``points`` (start, goal, threats) are given in metres from ``origin``.

    Raises:
        InputError: the DEM cannot be read, placed, or does not cover the area (one line, naming the file).
    """
    if origin is None:
        s, w, n, e = info(dem_path).bounds_latlon
        origin = Origin(lat=(s + n) / 2.0, lon=(w + e) / 2.0)
    if bounds is None:
        pts = np.asarray(points, dtype=float)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        d0 = math.dist(points[0], points[1])
        margin = max(MARGIN_SHARE * d0, MARGIN_MIN_M)
        area = (lo[0] - margin, lo[1] - margin, hi[0] + margin, hi[1] + margin)
    else:
        (x0, y0), (x1, y1) = bounds
        area = (x0, y0, x1, y1)
    dem = read_dem(dem_path, latlon_box(origin, area))
    rows, cols = dem.elevation.shape
    native = min(cell_metres(dem, rows // 2, cols // 2))
    cell = max(native, math.sqrt((area[2] - area[0]) * (area[3] - area[1]) / MAX_POINTS))
    grid = place(dem, origin, area, cell)
    ny, nx = grid.shape
    extent = ((grid.x0_m, grid.y0_m), (grid.x0_m + (nx - 1) * cell, grid.y0_m + (ny - 1) * cell))
    return PlanTerrain(
        dem_path,
        origin,
        grid,
        unit,
        TerrainSight(grid, unit.height_m),
        barrier_zones(grid, unit.max_slope_deg),
        bounds if bounds is not None else extent,
    )


def _samples(path: np.ndarray, spacing_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along ``path`` at most ``spacing_m`` apart (every vertex kept), and each piece's length."""
    seg = np.diff(path, axis=0)
    n = np.maximum(1, np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / spacing_m)).astype(np.int64)
    idx = np.repeat(np.arange(len(seg)), n)
    k = np.arange(len(idx)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n along each segment
    pts = np.concatenate([path[:1], path[idx] + (k / n[idx])[:, None] * seg[idx]])
    return pts, np.hypot(*np.diff(pts, axis=0).T)


@dataclass(frozen=True)
class _Ground:
    """A path sampled over the ground: its points every quarter cell, each piece's length and time."""

    pts: np.ndarray
    ds: np.ndarray
    dt: np.ndarray
    figures: dict[str, object]


def _walked(grid: TerrainGrid, path: np.ndarray, unit: Mobility) -> _Ground:
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    z = grid.elevation(path[:, 0], path[:, 1])
    pts, ds = _samples(path, 0.25 * grid.cell_m)
    zs = grid.elevation(pts[:, 0], pts[:, 1])
    dz = np.diff(zs)
    with np.errstate(invalid="ignore", divide="ignore"):
        grade = np.where(ds > 0, dz / np.where(ds > 0, ds, 1.0), 0.0)
        speed = speed_mps(unit, grade)
        dt = np.where(ds > 0, ds / speed, 0.0)
    slope = grid.slope_deg(pts[:, 0], pts[:, 1])
    eta = float(dt.sum())
    figures: dict[str, object] = {
        "path_elevation_m": [float(v) for v in z],
        "climb_m": float(np.nansum(np.maximum(dz, 0.0))),
        "max_slope_deg": float(np.nanmax(slope)) if np.isfinite(slope).any() else None,
        "eta_s": eta if math.isfinite(eta) else None,
    }
    return _Ground(pts, ds, dt, figures)


def over_ground(grid: TerrainGrid, path: np.ndarray, unit: Mobility) -> dict[str, object]:
    """A path's figures over the ground for a unit of ``unit``'s mobility, for ``msgspec.structs.replace`` of
    a ``PlanResult``: ``path_elevation_m`` at each point, ``climb_m``, ``max_slope_deg`` of the ground
    crossed and ``eta_s`` (every quarter cell, its length over the unit's speed on that grade,
    ``core.mobility.speed_mps``: its own flat speed scaled by its class's model)."""
    return _walked(grid, path, unit).figures


def exposure(
    path: np.ndarray, schedule: Sequence[Scheduled], intensity: Intensity, sight: object, per_step: bool
) -> float:
    """The path's exposure under the schedule's threats (pop-ups from their step when ``per_step``)."""
    if not per_step:
        field = ThreatField([s.threat for s in schedule], intensity, sight=sight)  # type: ignore[arg-type]
        return measure(path, [Epoch(0, len(path) - 1, field)]).exposure
    steps = sorted({0, *(s.appear_step for s in schedule)})
    epochs = []
    for a, b in zip(steps, [*steps[1:], max(len(path) - 1, steps[-1])], strict=True):
        active = [s.threat for s in schedule if s.appear_step <= a]
        field = ThreatField(active, intensity, sight=sight)  # type: ignore[arg-type]
        epochs.append(Epoch(min(a, len(path) - 1), min(b, len(path) - 1), field))
    return measure(path, epochs).exposure


def profile(
    result: PlanResult, terrain: PlanTerrain, schedule: Sequence[Scheduled], intensity: Intensity
) -> dict[str, object]:
    """The terrain fields of ``result`` (``PlanResult.path_elevation_m`` and the rest), for ``msgspec.structs.replace``."""
    path = np.asarray(result.path, dtype=float).reshape(-1, 2)
    ground = _walked(terrain.grid, path, terrain.unit)
    pts, ds, dt = ground.pts, ground.ds, ground.dt
    field = ThreatField([s.threat for s in schedule], intensity, sight=terrain.sight)
    mid = 0.5 * (pts[:-1] + pts[1:])
    views = []
    for j, t in enumerate(field.threats):
        row = field.packed[j]
        x0, y0, x1, y1 = reach_box(row)
        near = (mid[:, 0] >= x0) & (mid[:, 0] <= x1) & (mid[:, 1] >= y0) & (mid[:, 1] <= y1)
        seen = near.copy()
        if row[kernels.VIS_NX] > 0:
            packed = np.ascontiguousarray(field.packed[j : j + 1])
            for i in np.flatnonzero(near):
                seen[i] = kernels.sight(packed, 0, float(mid[i, 0]), float(mid[i, 1]), False)[0] >= 0.5
        views.append(ThreatView(t.id, float(ds[seen].sum()), float(dt[seen].sum())))
    return {
        **ground.figures,
        "in_view": views,
        "exposure_unmasked": exposure(path, schedule, intensity, None, result.planner == "pfp"),
    }
