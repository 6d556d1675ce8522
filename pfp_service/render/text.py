"""Text summaries of plan results for a terminal (no I/O).

Positions go through ``pfp_service.coords``: lat/lon (and the metres from
the origin) when the scenario has one, else metres.
"""

from __future__ import annotations

import re

from pfp_service.coords import Coords
from pfp_service.core import PlanResult

_UNIT_AT = re.compile(r"^step (\d+):(.*); unit at \([^)]*\)$")


def _m(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4g} m"


def _event(text: str, r: PlanResult, coords: Coords) -> str:
    """A plan event with the unit's position in ``coords`` (the core writes it in metres)."""
    m = _UNIT_AT.match(text)
    if m is None or not coords.geodetic or int(m[1]) >= len(r.path):
        return text
    return f"step {m[1]}:{m[2]}; unit at {coords.point(r.path[int(m[1])])}"


def summary(
    name: str,
    r: PlanResult,
    plot: str | None = None,
    coords: Coords | None = None,
    start: tuple[float, float] | None = None,
    goal: tuple[float, float] | None = None,
) -> str:
    """A short multi-line summary of one plan.

    Args:
        name: the scenario's name.
        r: the plan.
        plot: the PNG written, if any.
        coords: how positions are shown (default: metres).
        start: the scenario's start, shown with the goal and where the path ended.
        goal: the scenario's goal.
    """
    coords = coords or Coords()
    p = r.params
    lines = [
        f"{name}: {r.status.value}" + (f" ({r.reason})" if r.reason else ""),
    ]
    if start is not None and goal is not None:
        lines += [f"  start {coords.point(start, digits=2)}", f"  goal  {coords.point(goal, digits=2)}"]
    if r.path:
        lines.append(f"  end   {coords.point(r.path[-1], digits=2)}")
    lines += [
        f"  steps {r.steps}, length {_m(r.length)}, final distance {_m(r.final_distance)}",
        f"  exposure {r.exposure:.4g}, peak threat {r.peak_threat:.4g}, min clearance {_m(r.min_clearance)}"
        + (f", min zone clearance {_m(r.min_zone_clearance)}" if r.min_zone_clearance is not None else ""),
        (
            f"  planner optimal, lambda {r.lam:g}, grid {p.step:.4g} m, intensity {p.intensity}"
            if r.planner == "optimal" and r.lam is not None
            else f"  delta {p.delta:.4g}, step {p.step:.4g} m, tolerance {p.tolerance:.4g} m, "
            f"max_iter {p.max_iter}, intensity {p.intensity}, escape {p.escape}"
        ),
        f"  compute {r.compute_ms:.3f} ms",
    ]
    if r.climb_m is not None:  # planned over terrain
        eta = f"{r.eta_s / 60:.1f} min" if r.eta_s is not None else "unknown"
        steepest = f"{r.max_slope_deg:.1f} deg" if r.max_slope_deg is not None else "unknown"
        blind = f"{r.exposure_unmasked:.4g}" if r.exposure_unmasked is not None else "unknown"
        lines.append(
            f"  terrain: climb {_m(r.climb_m)}, steepest ground {steepest}, eta {eta}, "
            f"exposure {blind} if the threats saw through the ground"
        )
        if r.in_view:
            lines.append(
                "  in view: " + ", ".join(f"{v.id} {_m(v.metres)} ({v.seconds:.0f} s)" for v in r.in_view)
            )

    if r.traps:
        lines.append(
            f"  traps {r.traps}, escapes {', '.join(r.escapes) or 'none'}, {r.escape_steps} steps escaping"
        )
    lines += [f"  event: {_event(e, r, coords)}" for e in r.events]
    if plot:
        lines.append(f"  plot written to {plot}")
    return "\n".join(lines)
