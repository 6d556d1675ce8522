"""Several units' tracks over one threat field, as a PNG: ``pfp report`` and ``pfp demo`` draw it.

Drawn with the pieces every figure shares (``plots``: contours, zones, threat marks, frame,
legend), as ``plots.plan_figure`` draws one planned path.  matplotlib is imported only when a
figure is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pfp_service.coords import Coords
from pfp_service.core.threat import ThreatField
from pfp_service.render.geo_axes import frame
from pfp_service.render.plots import (
    colourbar,
    contours,
    draw_zones,
    extent,
    legend,
    peak,
    proxies,
    pyplot,
    save_png,
    threat_marks,
    zone_corners,
)

if TYPE_CHECKING:
    from pfp_service.core.threat import Threat
    from pfp_service.core.zones import Zone

__all__ = ["plot_tracks", "tracks_figure"]


def plot_tracks(
    threats: Sequence[Threat],
    intensity: str,
    tracks: dict[str, Sequence[Sequence[float]]],
    goals: dict[str, Sequence[float]],
    out: str | Path,
    **figure: Any,
) -> None:
    """``tracks_figure(threats, intensity, tracks, goals, **figure)`` written to the PNG ``out``."""
    plt = pyplot()
    fig = tracks_figure(threats, intensity, tracks, goals, **figure)
    try:
        save_png(fig, out, "--out")
    finally:
        plt.close(fig)


def tracks_figure(
    threats: Sequence[Threat],
    intensity: str,
    tracks: dict[str, Sequence[Sequence[float]]],
    goals: dict[str, Sequence[float]],
    title: str = "",
    marks: Sequence[tuple[float, float, str]] = (),
    old_threats: Sequence[tuple[Threat, Threat]] = (),
    old_goals: dict[str, Sequence[float]] | None = None,
    coords: Coords | None = None,
    zones: Sequence[Zone] = (),
    popups: dict[str, str] | None = None,
) -> Any:
    """Several units' tracks over one threat field, with labelled marks (e.g. contingencies).

    Args:
        threats: the threats in force at the end, drawn at their peaks.
        intensity: the field's intensity scale.
        tracks: each unit's positions, in order.
        goals: each unit's final goal.
        title: the plot's title.
        marks: ``(x, y, label)`` stars, e.g. where a contingency struck.
        old_threats: ``(before, after)`` for each threat that moved: ``before`` is drawn faded,
            with a dotted line to where it went.
        old_goals: goals a unit had before it was given a new one, drawn faded.
        coords: with an origin (geodetic), lat/lon ticks on the axes.
        zones: keep-out zones, hatched.
        popups: threat id -> when it appeared (e.g. ``"from 312 s"``): those threats are drawn
            orange with that label, not as if there from the start.

    Returns:
        the matplotlib figure (the caller saves and closes it).
    """
    plt = pyplot()
    old_goals = old_goals or {}
    popups = popups or {}
    field = ThreatField(threats, intensity)  # type: ignore[arg-type]
    pts = [p for tr in tracks.values() for p in tr] + list(goals.values()) + list(old_goals.values())
    pts += zone_corners(zones)
    box = extent(pts or [(0.0, 0.0)], [*threats, *(b for b, _ in old_threats)])
    fig, ax = plt.subplots(figsize=(9.4, 8.4), dpi=110)
    mappable = contours(ax, field, box)
    drawn = draw_zones(ax, zones)
    threat_marks(ax, [t for t in threats if t.id not in popups], intensity)
    for t in threats:
        if t.id in popups:
            threat_marks(ax, [t], intensity, label=f"({popups[t.id]})", colour="orange")
    for before, after in old_threats:
        threat_marks(ax, [before], intensity, label="(before it moved)", faded=True)
        (bx, by), (ax_, ay) = peak(before, intensity), peak(after, intensity)
        ax.plot([bx, ax_], [by, ay], ":", color="black", alpha=0.5, linewidth=1)
    handles = []
    for uid, tr in tracks.items():
        arr = np.asarray(tr, dtype=float).reshape(-1, 2)
        if len(arr):
            (line,) = ax.plot(arr[:, 0], arr[:, 1], "-", linewidth=1.2, label=uid)
            handles.append(line)
            colour = line.get_color()
            ax.plot(arr[0, 0], arr[0, 1], "o", color=colour, markersize=6)
            if uid in goals:
                ax.plot(*goals[uid], "s", color=colour, markeredgecolor="black", markersize=8)
            if uid in old_goals:
                ax.plot(*old_goals[uid], "s", color=colour, alpha=0.35, markersize=8)
                if uid in goals:
                    (gx, gy), (hx, hy) = old_goals[uid], goals[uid]
                    ax.plot([gx, hx], [gy, hy], ":", color=colour, alpha=0.5, linewidth=1)
    for x, y, label in marks:
        ax.plot([x], [y], marker="*", color="orange", markersize=15, markeredgecolor="black", zorder=5)
        ax.annotate(label, (x, y), textcoords="offset points", xytext=(8, -12), fontsize=8)
    kinds = ["start", "goal", "threat"]
    if popups:
        kinds.append("popup")
    if old_goals:
        kinds.append("old goal")
    if old_threats:
        kinds.append("old threat")
    if marks:
        kinds.append("struck")
    if drawn:
        kinds.append("zone")
    geo = frame(ax, box, title, coords)
    legend(ax, handles + proxies(plt, *kinds), geo)
    colourbar(fig, ax, mappable, geo)
    fig.tight_layout()
    return fig
