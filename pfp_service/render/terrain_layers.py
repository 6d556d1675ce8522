"""The ground under a plan's plot: hillshade, elevation contours, and where each threat can see.

``hillshade`` is the Lambertian shade of a ``terrain.grid.TerrainGrid`` lit by
a distant sun: the cosine between the ground's normal and the direction of
the sun, 0 where the ground faces away from it.  ``sight_masks`` gives, per
threat, the cells of its window (``core.visibility.Window``, what the planner
masked it with, spanning its reach) where it sees a unit of the plan's class:
the ground the plan's ``in_view`` metres and seconds are counted on.
``draw_terrain`` puts both under a plan's threats and path (``plots.plan_figure``)
and returns the legend entries.  Only drawing touches matplotlib.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pfp_service.core.threat import Threat, ThreatField
from pfp_service.core.visibility import reach_box

if TYPE_CHECKING:
    from pfp_service.terrain.grid import TerrainGrid
    from pfp_service.terrain.planning import PlanTerrain

__all__ = [
    "SUN_ALTITUDE_DEG",
    "SUN_AZIMUTH_DEG",
    "SightMask",
    "draw_terrain",
    "hillshade",
    "sight_masks",
]

# The cartographers' convention (and GDAL's gdaldem default): light from the
# north-west, 45 degrees up, so ridges read as raised rather than as troughs.
SUN_AZIMUTH_DEG = 315.0
SUN_ALTITUDE_DEG = 45.0
# Colours for the threats' shading, none of them the threat level's reds.
SEEN_COLOURS = ("tab:blue", "tab:purple", "tab:cyan", "tab:olive", "tab:pink", "tab:green")


def hillshade(
    z: np.ndarray, cell_m: float, azimuth_deg: float = SUN_AZIMUTH_DEG, altitude_deg: float = SUN_ALTITUDE_DEG
) -> np.ndarray:
    """How brightly a sun lights each cell of ``z`` (rows running north, as ``TerrainGrid.z``), 0 to 1.

    Args:
        z: elevations in metres, ``z[j, i]`` at ``i`` cells east and ``j`` north; NaN unknown.
        cell_m: the grid's spacing.
        azimuth_deg: where the sun is, compass degrees (0 north, 90 east).
        altitude_deg: how high it is above the horizon.

    Returns:
        the cosine between the ground's normal and the sun's direction, clipped at 0 (ground facing
        away from the sun is unlit, not negatively lit); NaN next to unknown ground. Flat ground is
        ``sin(altitude)``, ground tilted straight at the sun by ``90 - altitude`` degrees is 1.
    """
    if z.ndim != 2 or min(z.shape) < 2:
        raise ValueError("hillshade needs a grid of at least 2 x 2 elevations")
    # central differences (one-sided at the edges): this is for the eye, not a hot path
    dz_dy, dz_dx = np.gradient(np.asarray(z, dtype=float), cell_m)
    az, alt = math.radians(azimuth_deg), math.radians(altitude_deg)
    sun = (math.sin(az) * math.cos(alt), math.cos(az) * math.cos(alt), math.sin(alt))
    # the upward normal of z(x, y) is (-dz/dx, -dz/dy, 1), normalised
    lit = (-dz_dx * sun[0] - dz_dy * sun[1] + sun[2]) / np.sqrt(dz_dx**2 + dz_dy**2 + 1.0)
    # a central difference skips the cell itself: its own unknown height must still show as unknown
    return np.asarray(np.where(np.isnan(z), np.nan, np.clip(lit, 0.0, 1.0)))


@dataclass(frozen=True)
class SightMask:
    """Where threat ``id`` sees the unit: ``seen[k, i]`` at ``(x0_m + i cell_m, y0_m + k cell_m)``."""

    id: str
    x0_m: float
    y0_m: float
    cell_m: float
    seen: np.ndarray

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(left, right, bottom, top) of the cells, for ``imshow``."""
        ny, nx = self.seen.shape
        h = self.cell_m / 2.0
        return (
            self.x0_m - h,
            self.x0_m + (nx - 1) * self.cell_m + h,
            self.y0_m - h,
            self.y0_m + (ny - 1) * self.cell_m + h,
        )


def sight_masks(threats: Sequence[Threat], intensity: str, terrain: PlanTerrain) -> list[SightMask]:
    """Per threat that has a window over ``terrain``, the cells where it sees the unit (``v >= 0.5``).

    The window is the one the planner masked the threat with (``terrain.sight``, cached), over the
    box of its reach, and ``v >= 0.5`` is where ``profile`` counts a path in view, so the shading
    shows where the plan's ``in_view`` figures come from. A threat with no window (off the terrain,
    on unknown ground) sees everywhere and gets no mask.
    """
    field = ThreatField(list(threats), intensity)  # type: ignore[arg-type]
    out = []
    for j, t in enumerate(field.threats):
        window = terrain.sight(t, reach_box(field.packed[j]))
        if window is None:
            continue
        # unknown ground hides nothing (docs/terrain.md): NaN is seen, as the planner prices it
        seen = np.nan_to_num(window.low_m, nan=0.0) <= window.height_m
        out.append(SightMask(t.id, window.x0_m, window.y0_m, window.cell_m, seen))
    return out


def _crop(
    grid: TerrainGrid, box: tuple[float, float, float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid's x and y coordinates and elevations within ``box`` (one cell beyond, so edges are drawn)."""
    ny, nx = grid.shape
    c = grid.cell_m
    i0 = max(0, math.floor((box[0] - grid.x0_m) / c) - 1)
    i1 = min(nx, math.ceil((box[1] - grid.x0_m) / c) + 2)
    j0 = max(0, math.floor((box[2] - grid.y0_m) / c) - 1)
    j1 = min(ny, math.ceil((box[3] - grid.y0_m) / c) + 2)
    xs = grid.x0_m + c * np.arange(i0, i1)
    ys = grid.y0_m + c * np.arange(j0, j1)
    return xs, ys, grid.z[j0:j1, i0:i1]


def draw_terrain(
    ax: Any,
    terrain: PlanTerrain,
    threats: Sequence[Threat],
    intensity: str,
    box: tuple[float, float, float, float],
) -> list[Any]:
    """Hillshade, elevation contours and each threat's seen ground on ``ax``, under everything else.

    Returns:
        the legend entries: the contours' interval, and one patch per threat's shading.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from matplotlib.ticker import MaxNLocator

    handles: list[Any] = []
    xs, ys, z = _crop(terrain.grid, box)
    if min(z.shape) < 2 or not np.isfinite(z).any():
        return handles
    c = terrain.grid.cell_m
    extent = (xs[0] - c / 2, xs[-1] + c / 2, ys[0] - c / 2, ys[-1] + c / 2)
    shade = np.ma.masked_invalid(hillshade(z, c))
    ax.imshow(
        shade,
        origin="lower",
        extent=extent,
        cmap="gray",
        vmin=0.0,
        vmax=1.0,
        interpolation="bilinear",
        zorder=0,
    )
    levels = MaxNLocator(10).tick_values(float(np.nanmin(z)), float(np.nanmax(z)))
    if len(levels) >= 2:
        lines = ax.contour(
            xs,
            ys,
            np.ma.masked_invalid(z),
            levels=levels,
            colors="saddlebrown",
            linewidths=0.5,
            alpha=0.7,
            zorder=1,
        )
        ax.clabel(lines, lines.levels[::2], fontsize=6, fmt="%d m")
        step = float(levels[1] - levels[0])
        handles.append(
            Line2D([], [], color="saddlebrown", linewidth=0.8, label=f"elevation, every {step:g} m")
        )
    for k, mask in enumerate(sight_masks(threats, intensity, terrain)):
        colour = SEEN_COLOURS[k % len(SEEN_COLOURS)]
        rgba = np.zeros((*mask.seen.shape, 4))
        rgba[mask.seen] = (*_rgb(colour), 0.3)
        ax.imshow(rgba, origin="lower", extent=mask.extent, interpolation="nearest", zorder=1.5)
        handles.append(Patch(facecolor=colour, alpha=0.3, label=f"{mask.id} sees a unit here"))
    return handles


def _rgb(colour: str) -> tuple[float, float, float]:
    from matplotlib.colors import to_rgb

    r, g, b = to_rgb(colour)
    return r, g, b
