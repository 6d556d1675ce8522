"""PNG plots of threat fields and paths (needs the ``plot`` extra: matplotlib)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pfp_service.core import PlanResult, Threat, ThreatField
from pfp_service.errors import InputError
from pfp_service.scenario import Scenario

__all__ = ["check_png_path", "extent", "plot_plan", "plot_tracks"]


def _pyplot() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise InputError("--plot", "needs matplotlib: pip install 'pfp-service[plot]'") from exc
    return plt


def check_png_path(path: str | Path, what: str) -> Path:
    """Refuse, before any work is done, an output path that cannot take a PNG.

    Raises:
        InputError: naming ``what`` (the flag), when the folder is missing or the suffix is not ``.png``.
    """
    p = Path(path)
    if p.suffix.lower() != ".png":
        raise InputError(what, f"{path}: must end in .png")
    if not p.parent.is_dir():
        raise InputError(what, f"{path}: folder {p.parent} does not exist")
    return p


def _save(fig: Any, out: str | Path, what: str) -> None:
    try:
        fig.savefig(out)
    except (OSError, ValueError) as exc:
        raise InputError(what, f"cannot write {out}: {exc}") from None


def extent(
    points: Sequence[Sequence[float]], threats: Sequence[Threat], margin: float = 0.08
) -> tuple[float, float, float, float]:
    """A box around ``points`` and each threat's 3-sigma zone."""
    xs = [p[0] for p in points]
    ys = [p[1] for p in points]
    for t in threats:
        r = 3.0 * max(t.omega[0][0], t.omega[1][1]) ** 0.5
        xs += [t.xi[0] - r, t.xi[0] + r]
        ys += [t.xi[1] - r, t.xi[1] + r]
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    pad = margin * max(x1 - x0, y1 - y0, 1e-9)
    return x0 - pad, x1 + pad, y0 - pad, y1 + pad


def _contours(ax: Any, field: ThreatField, box: tuple[float, float, float, float], n: int = 220) -> None:
    if not len(field):
        return
    x0, x1, y0, y1 = box
    gx, gy = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    level = field.level(np.stack([gx, gy], axis=-1))
    top = float(level.max())
    if top <= 0:
        return
    ax.contourf(gx, gy, level, levels=np.linspace(top * 0.02, top, 12), cmap="Reds", alpha=0.55)
    ax.contour(gx, gy, level, levels=np.linspace(top * 0.05, top, 8), colors="darkred", linewidths=0.5)


def _popup_marks(ax: Any, result: PlanResult) -> None:
    for ev in result.events:
        m = re.match(r"step (\d+):", ev)
        if m and int(m[1]) < len(result.path):
            x, y = result.path[int(m[1])]
            ax.plot([x], [y], marker="*", color="orange", markersize=14, markeredgecolor="black", zorder=5)


def plot_plan(scenario: Scenario, result: PlanResult, out: str | Path) -> None:
    """Threat contours (all threats, pop-ups included), start, goal and the path."""
    plt = _pyplot()
    threats = [s.threat for s in scenario.schedule()]
    field = ThreatField(threats, result.params.intensity)  # type: ignore[arg-type]
    box = extent([scenario.start, scenario.goal, *result.path], threats)
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    _contours(ax, field, box)
    for s in scenario.schedule():
        t = s.threat
        style = dict(marker="^", color="red" if s.appear_step == 0 else "orange", markeredgecolor="black")
        ax.plot([t.xi[0]], [t.xi[1]], linestyle="none", markersize=9, **style)
        label = t.id + (f" (step {s.appear_step})" if s.appear_step else "")
        ax.annotate(label, t.xi, textcoords="offset points", xytext=(6, 6), fontsize=8)
    path = np.asarray(result.path)
    ax.plot(path[:, 0], path[:, 1], ".-", color="navy", markersize=2, linewidth=1, label="path")
    _popup_marks(ax, result)
    ax.plot(*scenario.start, "o", color="green", markersize=9, label="start")
    ax.plot(*scenario.goal, "s", color="black", markersize=9, label="goal")
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    ax.set_title(
        f"{scenario.name}: {result.status.value}, {result.steps} steps, exposure {result.exposure:.3g}"
    )
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    try:
        _save(fig, out, "--plot")
    finally:
        plt.close(fig)


def plot_tracks(
    threats: Sequence[Threat],
    intensity: str,
    tracks: dict[str, Sequence[Sequence[float]]],
    goals: dict[str, Sequence[float]],
    out: str | Path,
    title: str = "",
    marks: Sequence[tuple[float, float, str]] = (),
) -> None:
    """Several units' tracks over one threat field, with labelled marks (e.g. contingencies)."""
    plt = _pyplot()
    field = ThreatField(threats, intensity)  # type: ignore[arg-type]
    pts = [p for tr in tracks.values() for p in tr] + list(goals.values())
    box = extent(pts or [(0.0, 0.0)], threats)
    fig, ax = plt.subplots(figsize=(8, 8), dpi=110)
    _contours(ax, field, box)
    for t in threats:
        ax.plot([t.xi[0]], [t.xi[1]], "^", color="red", markeredgecolor="black", markersize=9)
        ax.annotate(t.id, t.xi, textcoords="offset points", xytext=(6, 6), fontsize=8)
    for uid, tr in tracks.items():
        arr = np.asarray(tr, dtype=float).reshape(-1, 2)
        if len(arr):
            (line,) = ax.plot(arr[:, 0], arr[:, 1], "-", linewidth=1.2, label=uid)
            ax.plot(arr[0, 0], arr[0, 1], "o", color=line.get_color(), markersize=6)
            if uid in goals:
                ax.plot(*goals[uid], "s", color=line.get_color(), markeredgecolor="black", markersize=8)
    for x, y, label in marks:
        ax.plot([x], [y], marker="*", color="orange", markersize=15, markeredgecolor="black", zorder=5)
        ax.annotate(label, (x, y), textcoords="offset points", xytext=(8, -12), fontsize=8)
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    ax.set_title(title)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    try:
        _save(fig, out, "--out")
    finally:
        plt.close(fig)
