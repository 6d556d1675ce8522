"""``pfp report --terrain DEM``: each unit's track measured over the ground.

Per unit, on its recorded track:

- ``climb_m``: the sum of every rise along the track, the ground sampled
  bilinearly at most a quarter of a terrain cell apart (descents are not netted
  off: a unit that climbs 100 m and comes down again climbed 100 m);
- ``max_slope_deg``: the steepest ground the track crosses (the DEM's slope at
  those samples, not the track's own grade);
- ``in_view_s``: per threat, the seconds of the track it could see: a segment
  counts when, at its midpoint and under the threat versions in force then,
  the unit is within the threat's reach (``core.visibility.reach_box``, as the
  planner's in-view metres) and an exact ray (``terrain.viewshed``'s R3) from
  the threat's eye (``observer_height_m`` above its ground) clears the ground
  to the unit's height (its class's ``height_m``).  A threat on unknown ground
  sees (the safe side, as in the planner).  Seconds are on the report's clock
  (the units' own when every state carries ``t``).

The DEM is read under the box of the tracks and threats (500 m round it), at
its own resolution or coarser, as ``pfp plan --terrain`` places it
(``terrain.planning``); a DEM that does not cover that box is refused with one
line naming the file.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pfp_clients.watch import Watch
from pfp_service.core.mobility import Mobility
from pfp_service.geo import Origin
from pfp_service.terrain.grid import TerrainGrid

__all__ = ["MARGIN_M", "GroundSummary", "Terrain", "load", "measure_ground"]

MARGIN_M = 500.0


@dataclass(frozen=True)
class Terrain:
    """The DEM placed under the record, and the unit class it is measured for."""

    path: str
    grid: TerrainGrid
    unit: Mobility


@dataclass
class GroundSummary:
    """One unit's track over the ground."""

    climb_m: float = 0.0
    max_slope_deg: float | None = None
    in_view_s: dict[str, float] = field(default_factory=dict)


def load(path: str, origin: Origin, points: Sequence[tuple[float, float]], unit: Mobility) -> Terrain:
    """The DEM's window under ``points`` (metres from ``origin``) with ``MARGIN_M`` round them.

    Raises:
        InputError: path ``path``: not a DEM, or not covering the points.
    """
    from pfp_service.terrain.dem import read_dem
    from pfp_service.terrain.grid import latlon_box, place
    from pfp_service.terrain.planning import MAX_POINTS
    from pfp_service.terrain.sight import cell_metres

    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    lo, hi = pts.min(axis=0) - MARGIN_M, pts.max(axis=0) + MARGIN_M
    area = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    dem = read_dem(path, latlon_box(origin, area))
    rows, cols = dem.elevation.shape
    native = min(cell_metres(dem, rows // 2, cols // 2))
    cell = max(native, math.sqrt((area[2] - area[0]) * (area[3] - area[1]) / MAX_POINTS))
    return Terrain(path, place(dem, origin, area, cell), unit)


def _samples(path: np.ndarray, spacing_m: float) -> np.ndarray:
    out = [path[:1]]
    for a, b in itertools.pairwise(path):
        n = max(1, math.ceil(math.dist(a, b) / spacing_m))
        out.append(a + (np.arange(1, n + 1)[:, None] / n) * (b - a))
    return np.concatenate(out)


def measure_ground(
    terrain: Terrain,
    tracks: dict[str, list[tuple[float, float, float]]],
    times: dict[str, list[float]],
    watch: Watch,
) -> dict[str, GroundSummary]:
    """Per unit, its climb, steepest ground and time in view of each threat.

    Args:
        tracks: per unit, ``(record s, x, y)`` in order.
        times: per unit, the time of each track point on the report's clock.
    """
    from pfp_service.core.threat import ThreatField
    from pfp_service.core.visibility import reach_box
    from pfp_service.terrain.viewshed import exact_lowest_visible_height

    g = terrain.grid
    out: dict[str, GroundSummary] = {}
    for unit, track in tracks.items():
        s = out[unit] = GroundSummary()
        if len(track) < 2:
            continue
        xy = np.array([(x, y) for _t, x, y in track], dtype=float)
        pts = _samples(xy, 0.25 * g.cell_m)
        z = g.elevation(pts[:, 0], pts[:, 1])
        s.climb_m = float(np.nansum(np.maximum(np.diff(z), 0.0)))
        slope = g.slope_deg(pts[:, 0], pts[:, 1])
        s.max_slope_deg = float(np.nanmax(slope)) if np.isfinite(slope).any() else None
        mid = 0.5 * (xy[:-1] + xy[1:])
        dt = np.diff(np.asarray(times[unit], dtype=float))
        at = [0.5 * (a[0] + b[0]) for a, b in itertools.pairwise(track)]
        by_version: dict[int, list[int]] = {}
        versions = {}
        for i, t in enumerate(at):
            for v in watch.in_force(t):
                by_version.setdefault(id(v), []).append(i)
                versions[id(v)] = v
        for key, idx in by_version.items():
            v = versions[key]
            threat = v.threat()
            x0, y0, x1, y1 = reach_box(ThreatField([threat], "peak").packed[0])
            sel = np.array(idx)
            m = mid[sel]
            near = (m[:, 0] >= x0) & (m[:, 0] <= x1) & (m[:, 1] >= y0) & (m[:, 1] <= y1)
            seen = near.copy()
            try:
                eye = g.cell_of(*threat.xi)
            except ValueError:
                eye = None
            if eye is not None and math.isfinite(g.z[eye]) and near.any():
                cells = np.array([_nearest(g, p) for p in m[near]])
                ok = (cells >= 0).all(axis=1)
                low = np.zeros(len(cells))
                low[ok] = exact_lowest_visible_height(
                    g.z, eye, threat.observer_height_m, cells[ok], g.cell_m, g.cell_m
                )
                seen[np.flatnonzero(near)] = low <= terrain.unit.height_m
            s.in_view_s[v.threat_id] = s.in_view_s.get(v.threat_id, 0.0) + float(dt[sel][seen].sum())
    return out


def _nearest(g: TerrainGrid, p: np.ndarray) -> tuple[int, int]:
    try:
        return g.cell_of(float(p[0]), float(p[1]))
    except ValueError:
        return (-1, -1)  # off the grid: unknown ground, seen
