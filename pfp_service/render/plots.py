"""PNG plots of threat fields and paths (needs the ``plot`` extra: matplotlib).

Every plot has the same furniture: threat level as filled contours with a
colour bar, each threat at its peak with an arrow along its facing, start
(circle) and goal (square) markers in the legend, and the legend beside the
axes so it never covers the data.  Earlier positions of moved threats and
earlier goals are drawn faded; a plan that did not reach its goal marks
where it stopped, with the reason.  Keep-out zones are hatched grey, each
labelled with its id and "no-go" (the artist's gid is ``zone:ID``); a threat
that popped up mid-run is orange, labelled with when it appeared.

With a mission origin (``coords.Coords`` geodetic), the bottom and left axes
carry longitude and latitude ticks at round values along those edges, with a
faint graticule, and the top and right axes keep the metres from the origin
(``geo_axes``).  A plan over terrain is drawn on its ground: hillshade,
elevation contours and the ground each threat sees (``terrain_layers``), its
threat level is the one masked by line of sight, and the terrain's slope
barriers are hatched lightly with one legend entry instead of a label each.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pfp_service.coords import Coords
from pfp_service.core import PlanResult, Threat, ThreatField
from pfp_service.core.zones import Zone
from pfp_service.errors import InputError
from pfp_service.render.geo_axes import frame
from pfp_service.scenario import Scenario

if TYPE_CHECKING:
    from pfp_service.terrain.planning import PlanTerrain

__all__ = [
    "check_png_path",
    "colourbar",
    "contours",
    "draw_zones",
    "extent",
    "facing",
    "legend",
    "peak",
    "plan_figure",
    "plan_title",
    "plot_plan",
    "proxies",
    "pyplot",
    "save_png",
    "threat_marks",
    "zone_corners",
]

ZONE_STYLE: dict[str, Any] = dict(facecolor="0.55", edgecolor="black", alpha=0.45, hatch="xx", linewidth=1.0)
# a terrain's barriers (too steep, or unknown ground): hatched lightly, so the ground shows through
BARRIER_STYLE: dict[str, Any] = dict(
    facecolor="none", edgecolor="black", alpha=0.5, hatch="////", linewidth=0.3
)


def pyplot() -> Any:
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


def save_png(fig: Any, out: str | Path, what: str) -> None:
    try:
        fig.savefig(out, bbox_inches="tight")  # the legend sits beside the axes
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


def zone_corners(zones: Sequence[Zone]) -> list[tuple[float, float]]:
    """Two corners of each zone's box, for ``extent``: a plot shows every zone it draws whole."""
    out: list[tuple[float, float]] = []
    for z in zones:
        x0, y0, x1, y1 = z.bounds()
        out += [(x0, y0), (x1, y1)]
    return out


def draw_zones(
    ax: Any, zones: Sequence[Zone], style: dict[str, Any] = ZONE_STYLE, labelled: bool = True
) -> int:
    """Each keep-out zone as a hatched patch (holes left open) labelled ``ID (no-go)``; returns how many.

    ``labelled=False`` draws them unnamed: a terrain's slope barriers are dozens of small
    polygons, and one legend entry says what they all are.
    """
    from matplotlib.patches import Circle, PathPatch
    from matplotlib.path import Path as MPath

    for z in zones:
        if z.centre is not None:
            patch: Any = Circle(z.centre, z.radius_m, **style)
            at = z.centre
        else:
            verts: list[tuple[float, float]] = []
            codes: list[int] = []
            for ring in z.rings():
                verts += [*ring, ring[0]]
                codes += [int(MPath.MOVETO)] + [int(MPath.LINETO)] * (len(ring) - 1) + [int(MPath.CLOSEPOLY)]
            patch = PathPatch(MPath(verts, codes), **style)
            c = z.geometry.representative_point()
            at = (float(c.x), float(c.y))
        patch.set_gid(f"zone:{z.id}")
        patch.set_zorder(3)
        ax.add_patch(patch)
        if not labelled:
            continue
        ax.annotate(
            f"{z.id} (no-go)", at, fontsize=8, ha="center", va="center", zorder=4,
            bbox=dict(boxstyle="round", fc="white", ec="none", alpha=0.7),
        )  # fmt: skip
    return len(zones)


def peak(threat: Threat, intensity: str, n: int = 161) -> tuple[float, float]:
    """Where one threat's own level is highest: its mode, which a skewed threat has off ``xi``."""
    r = 3.0 * max(threat.omega[0][0], threat.omega[1][1]) ** 0.5
    x0, y0 = threat.xi
    gx, gy = np.meshgrid(np.linspace(x0 - r, x0 + r, n), np.linspace(y0 - r, y0 + r, n))
    level = ThreatField([threat], intensity).level(np.stack([gx, gy], axis=-1))  # type: ignore[arg-type]
    i = np.unravel_index(int(np.argmax(level)), level.shape)
    return float(gx[i]), float(gy[i])


def facing(threat: Threat) -> tuple[float, float] | None:
    """The unit vector a skewed threat faces (where its field reaches out); None without skew."""
    ax, ay = threat.shape()
    norm = float(np.hypot(ax, ay))
    return None if norm == 0.0 else (ax / norm, ay / norm)


def contours(
    ax: Any, field: ThreatField, box: tuple[float, float, float, float], n: int = 220, alpha: float = 0.55
) -> Any:
    """Filled contours of the threat level; returns the mappable for a colour bar (None if flat)."""
    if not len(field):
        return None
    x0, x1, y0, y1 = box
    gx, gy = np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n))
    level = field.level(np.stack([gx, gy], axis=-1))
    top = float(level.max())
    if top <= 0:
        return None
    filled = ax.contourf(gx, gy, level, levels=np.linspace(top * 0.02, top, 12), cmap="Reds", alpha=alpha)
    ax.contour(gx, gy, level, levels=np.linspace(top * 0.05, top, 8), colors="darkred", linewidths=0.5)
    return filled


def threat_marks(
    ax: Any,
    threats: Sequence[Threat],
    intensity: str,
    label: str = "",
    faded: bool = False,
    colour: str = "red",
) -> None:
    """Each threat at its peak with an arrow along its facing; faded ones are earlier positions."""
    alpha = 0.35 if faded else 1.0
    for t in threats:
        px, py = peak(t, intensity)
        ax.plot(
            [px], [py], "^", color=colour, markeredgecolor="black", markersize=9, alpha=alpha, zorder=4,
            linestyle="none",
        )  # fmt: skip
        d = facing(t)
        if d is not None:
            length = 1.5 * max(t.omega[0][0], t.omega[1][1]) ** 0.5
            ax.annotate(
                "",
                xy=(px + length * d[0], py + length * d[1]),
                xytext=(px, py),
                arrowprops=dict(arrowstyle="-|>", color="black", lw=1.2, alpha=alpha),
                zorder=4,
            )
        text = t.id + (f" {label}" if label else "")
        ax.annotate(text, (px, py), textcoords="offset points", xytext=(6, 6), fontsize=8, alpha=alpha)


def legend(ax: Any, handles: list[Any], geo: bool = False) -> None:
    """The legend beside the axes, so it never covers a track, a goal or a threat (nor the metres axis)."""
    ax.legend(
        handles=handles, loc="upper left", bbox_to_anchor=(1.14 if geo else 1.02, 1.0), fontsize=8,
        borderaxespad=0.0,
    )  # fmt: skip


def proxies(plt: Any, *kinds: str) -> list[Any]:
    """Legend entries for the markers (start, goal, threat ...), drawn in grey."""
    from matplotlib.lines import Line2D

    style: dict[str, dict[str, Any]] = {
        "start": dict(marker="o", color="grey", label="start"),
        "goal": dict(marker="s", color="grey", markeredgecolor="black", label="goal"),
        "old goal": dict(marker="s", color="grey", alpha=0.35, label="goal before it changed"),
        "threat": dict(marker="^", color="red", markeredgecolor="black", label="threat peak, arrow: facing"),
        "popup": dict(marker="^", color="orange", markeredgecolor="black", label="pop-up threat"),
        "old threat": dict(marker="^", color="red", alpha=0.35, label="threat before it moved"),
        "struck": dict(
            marker="*", color="orange", markeredgecolor="black", markersize=12, label="contingency"
        ),
        "stuck": dict(marker="X", color="black", markersize=10, label="where the plan stopped"),
    }
    out: list[Any] = []
    for k in kinds:
        if k == "zone":
            from matplotlib.patches import Patch

            out.append(Patch(**ZONE_STYLE, label="keep-out zone (no-go)"))
        else:
            out.append(Line2D([], [], linestyle="none", **{"markersize": 8, **style[k]}))
    return out


def colourbar(fig: Any, ax: Any, mappable: Any, geo: bool = False, label: str = "threat level") -> None:
    if mappable is not None:
        fig.colorbar(
            mappable,
            ax=ax,
            orientation="horizontal",
            fraction=0.04,
            pad=0.11 if geo else 0.08,
            label=label,
            format="%.2g",
        )


def _popup_marks(ax: Any, result: PlanResult) -> int:
    """A star where the unit was when each pop-up threat appeared; returns how many."""
    drawn = 0
    for ev in result.events:
        m = re.match(r"step (\d+):", ev)
        if m and int(m[1]) < len(result.path):
            x, y = result.path[int(m[1])]
            ax.plot([x], [y], marker="*", color="orange", markersize=14, markeredgecolor="black", zorder=5)
            drawn += 1
    return drawn


def plan_title(name: str, result: PlanResult) -> str:
    """``paper: pfp (escape auto), reached, 144 steps, exposure 0.0133``; the optimal names its λ."""
    if result.planner == "optimal":
        planner = f"optimal (λ = {result.lam:g})" if result.lam is not None else "optimal"
    else:
        planner = f"pfp (escape {result.params.escape})"
    return f"{name}: {planner}, {result.status.value}, {result.steps} steps, exposure {result.exposure:.3g}"


def plot_plan(
    scenario: Scenario,
    result: PlanResult,
    out: str | Path,
    coords: Coords | None = None,
    zones: Sequence[Zone] | None = None,
    terrain: PlanTerrain | None = None,
) -> None:
    """``plan_figure`` written to the PNG ``out``."""
    plt = pyplot()
    fig = plan_figure(scenario, result, coords, zones, terrain)
    try:
        save_png(fig, out, "--plot")
    finally:
        plt.close(fig)


def plan_figure(
    scenario: Scenario,
    result: PlanResult,
    coords: Coords | None = None,
    zones: Sequence[Zone] | None = None,
    terrain: PlanTerrain | None = None,
) -> Any:
    """Threat contours (all threats, pop-ups included), keep-out zones, start, goal, the path, and where it stopped.

    Args:
        zones: the zones the plan kept out of (the scenario's, ``--zones`` and the terrain's barriers);
            the scenario's and the terrain's when ``None``.
        coords: geodetic: the axes carry lat/lon ticks (and the metres on the top and right).
        terrain: the ground it was planned over: drawn under it, and the threat level masked by sight.

    Returns:
        the matplotlib figure (the caller saves and closes it).
    """
    plt = pyplot()
    intensity = result.params.intensity
    schedule = scenario.schedule()
    threats = [s.threat for s in schedule]
    kept_out = list(scenario.zone_set() if zones is None else zones)
    if zones is None and terrain is not None:
        kept_out += terrain.zones
    barrier_ids = {z.id for z in terrain.zones} if terrain is not None else set()
    barriers = [z for z in kept_out if z.id in barrier_ids]
    kept_out = [z for z in kept_out if z.id not in barrier_ids]
    sight = terrain.sight if terrain is not None else None
    field = ThreatField(threats, intensity, sight=sight)  # type: ignore[arg-type]
    box = extent([scenario.start, scenario.goal, *result.path, *zone_corners(kept_out)], threats)
    fig, ax = plt.subplots(figsize=(8.6, 7.4), dpi=110)
    ground: list[Any] = []
    if terrain is not None:
        from pfp_service.render.terrain_layers import draw_terrain

        ground = draw_terrain(ax, terrain, threats, intensity, box)
    # over terrain, lighter, so the ground shows through the threat level
    mappable = contours(ax, field, box, alpha=0.55 if terrain is None else 0.4)
    drawn = draw_zones(ax, kept_out)
    if barriers and terrain is not None:
        from matplotlib.patches import Patch

        draw_zones(ax, barriers, BARRIER_STYLE, labelled=False)
        unknown = " or unknown" if any(z.id.startswith("unknown-ground") for z in barriers) else ""
        what = f"ground steeper than {terrain.unit.max_slope_deg:g}°{unknown} (no-go, {terrain.unit.kind})"
        ground.append(Patch(**BARRIER_STYLE, label=what))
    known = [s.threat for s in schedule if s.appear_step == 0]
    threat_marks(ax, known, intensity)
    for s in schedule:
        if s.appear_step:
            threat_marks(ax, [s.threat], intensity, label=f"(step {s.appear_step})", colour="orange")
    path = np.asarray(result.path)
    (line,) = ax.plot(path[:, 0], path[:, 1], ".-", color="navy", markersize=2, linewidth=1, label="path")
    struck = _popup_marks(ax, result)
    ax.plot(*scenario.start, "o", color="green", markersize=9)
    ax.plot(*scenario.goal, "s", color="black", markersize=9)
    kinds = ["start", "goal", "threat"]
    if any(s.appear_step for s in schedule):
        kinds.append("popup")
    if struck:
        kinds.append("struck")
    if drawn:
        kinds.append("zone")
    if result.status.value != "reached":
        x, y = result.path[-1]
        ax.plot([x], [y], "X", color="black", markersize=12, zorder=6)
        why = result.status.value + (f": {result.reason}" if result.reason else "")
        ax.annotate(
            why, (x, y), textcoords="offset points", xytext=(8, -14), fontsize=8, zorder=6,
            bbox=dict(boxstyle="round", fc="white", ec="black", alpha=0.85),
        )  # fmt: skip
        kinds.append("stuck")
    handles = [line, *proxies(plt, *kinds)]
    handles[1].set_color("green")
    handles[2].set_color("black")
    geo = frame(ax, box, plan_title(scenario.name, result), coords)
    legend(ax, handles + ground, geo)
    level = "threat level" if terrain is None else "threat level, masked by line of sight"
    colourbar(fig, ax, mappable, geo, label=level)
    fig.tight_layout()
    return fig
