"""Axes in lat/lon for plots with a mission origin: round-degree ticks, a graticule, metres on the far sides.

Split from ``plots`` so that module keeps to drawing the field, the zones and the paths.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from pfp_service.coords import Coords

__all__ = ["frame", "geo_ticks"]


def frame(ax: Any, box: tuple[float, float, float, float], title: str, coords: Coords | None = None) -> bool:
    """Limits, aspect, title and axes; returns whether the axes are lat/lon (with a metres axis too)."""
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=10)
    if coords is not None and coords.origin is not None and coords.geodetic:
        _geo_ticks(ax, box, coords)
        return True
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    return False


def geo_ticks(
    box: tuple[float, float, float, float], coords: Coords, n: int = 8
) -> tuple[list[tuple[float, str]], list[tuple[float, str]]]:
    """Longitude ticks along the bottom edge and latitude ticks along the left one, at round values.

    Returns:
        ``([(x_m, "15.630°E"), ...], [(y_m, "58.415°N"), ...])``: where each round
        degree value crosses that edge, in local metres, and its label.
    """
    from matplotlib.ticker import MaxNLocator

    origin = coords.origin
    assert origin is not None
    x0, x1, y0, y1 = box
    lon_a, lon_b = origin.to_geodetic(x0, y0)[1], origin.to_geodetic(x1, y0)[1]
    (lat_c, _), (lat_d, _) = origin.to_geodetic(x0, y0), origin.to_geodetic(x0, y1)

    def rounded(lo: float, hi: float) -> list[float]:
        return [
            float(v) for v in MaxNLocator(n, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi) if lo <= v <= hi
        ]

    def decimals(values: list[float]) -> int:
        step = min((b - a for a, b in itertools.pairwise(values)), default=1.0)
        return max(0, min(6, -int(np.floor(np.log10(step))) if step > 0 else 6))

    xs: list[tuple[float, str]] = []
    lons = rounded(min(lon_a, lon_b), max(lon_a, lon_b))
    d = decimals(lons)
    for lon in lons:  # the x where the bottom edge (y = y0) meets this meridian: two fixed-point steps
        x = x0 + (x1 - x0) * (lon - lon_a) / ((lon_b - lon_a) or 1.0)
        for _ in range(3):
            lat, _lon = origin.to_geodetic(x, y0)
            x = origin.to_local(lat, lon)[0]
        xs.append((x, f"{abs(lon):.{d}f}°{'E' if lon >= 0 else 'W'}"))
    ys: list[tuple[float, str]] = []
    lats = rounded(min(lat_c, lat_d), max(lat_c, lat_d))
    d = decimals(lats)
    for lat in lats:  # the y where the left edge (x = x0) meets this parallel
        y = y0 + (y1 - y0) * (lat - lat_c) / ((lat_d - lat_c) or 1.0)
        for _ in range(3):
            _lat, lon = origin.to_geodetic(x0, y)
            y = origin.to_local(lat, lon)[1]
        ys.append((y, f"{abs(lat):.{d}f}°{'N' if lat >= 0 else 'S'}"))
    return xs, ys


def _geo_ticks(ax: Any, box: tuple[float, float, float, float], coords: Coords) -> None:
    """Longitude and latitude on the bottom and left axes, metres from the origin on the top and right."""
    xs, ys = geo_ticks(box, coords)
    ax.set_xticks([x for x, _ in xs], [t for _, t in xs])
    ax.set_yticks([y for y, _ in ys], [t for _, t in ys])
    ax.tick_params(axis="x", labelsize=7)
    ax.tick_params(axis="y", labelsize=7)
    ax.set_xlabel("longitude (WGS-84)")
    ax.set_ylabel("latitude (WGS-84)")
    ax.grid(True, color="grey", alpha=0.25, linewidth=0.5)
    top = ax.secondary_xaxis("top")
    top.set_xlabel("metres east of the origin", fontsize=8)
    top.tick_params(labelsize=7)
    right = ax.secondary_yaxis("right")
    right.set_ylabel("metres north of the origin", fontsize=8)
    right.tick_params(labelsize=7)
