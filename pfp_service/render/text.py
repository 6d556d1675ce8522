"""Text summaries of plan results for a terminal (no I/O)."""

from __future__ import annotations

from pfp_service.core import PlanResult


def _m(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.4g} m"


def summary(name: str, r: PlanResult, plot: str | None = None) -> str:
    """A short multi-line summary of one plan."""
    p = r.params
    lines = [
        f"{name}: {r.status.value}" + (f" ({r.reason})" if r.reason else ""),
        f"  steps {r.steps}, length {_m(r.length)}, final distance {_m(r.final_distance)}",
        f"  exposure {r.exposure:.4g}, peak threat {r.peak_threat:.4g}, min clearance {_m(r.min_clearance)}",
        (
            f"  planner optimal, lambda {r.lam:g}, grid {p.step:.4g} m, intensity {p.intensity}"
            if r.planner == "optimal" and r.lam is not None
            else f"  delta {p.delta:.4g}, step {p.step:.4g} m, tolerance {p.tolerance:.4g} m, "
            f"max_iter {p.max_iter}, intensity {p.intensity}, escape {p.escape}"
        ),
        f"  compute {r.compute_ms:.3f} ms",
    ]
    if r.traps:
        lines.append(
            f"  traps {r.traps}, escapes {', '.join(r.escapes) or 'none'}, {r.escape_steps} steps escaping"
        )
    lines += [f"  event: {e}" for e in r.events]
    if plot:
        lines.append(f"  plot written to {plot}")
    return "\n".join(lines)
