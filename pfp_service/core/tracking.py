"""Route tracking: what a live unit is steered along, whatever it does between two reports.

A real vehicle reports at its own rate (1-20 Hz), drives at its own speed,
stops, and its fix jitters by metres.  So the live stepper (``Stepper.track``)
never judges the field from how far the unit moved since its last report:
the planner's ``step`` is its own resolution, not the vehicle's.

* **Traps are facts of the field.**  The look-ahead (``foresight``)
  simulates plain descent from the unit's position at the planner's own
  resolution, with the step rule's trap watch; that simulation, not the
  vehicle's reports, says whether descent is trapped.
* **A route, once chosen, is tracked.**  The simulated descent (or the route
  round a trap, or the cheaper route) becomes the unit's route, kept as
  straight legs (``simplify``: no point of the descent lies more than
  ``SIMPLIFY_STEPS`` steps off them).  The unit is steered from wherever it
  reports towards the point of the route ``lead`` metres past its nearest
  one (pure pursuit), the lead growing with its speed (``LEAD_S`` seconds of
  driving, at least ``LEAD_STEPS`` steps), but never so far that the chord
  to it strays more than ``PURSUIT_TOLERANCE_STEPS`` steps from the route
  (``route_kernels._pursuit``: a bend shortens it); ``reach_m`` is how far that
  heading stays on the route: to the pursuit point.
* **A route is re-chosen** when the world changes, when the unit reports
  more than ``corridor(step)`` metres off it (a person drove it elsewhere),
  or at its end when it ended short of the goal.  GPS noise of a few metres
  is well inside the corridor, so it neither flips the route nor trips a trap.

``Route`` names what a route is, so a person can read why the unit goes
where it goes (``docs/wire.md``): only a way round a trap, a way out of a
core or zone, or an escape from a trap met are ``escaping``.
"""

from __future__ import annotations

import math
from enum import StrEnum

import numba
import numpy as np

__all__ = [
    "CORRIDOR_MIN_M",
    "CORRIDOR_STEPS",
    "LEAD_S",
    "LEAD_STEPS",
    "MAX_LEAD_POINTS",
    "PURSUIT_TOLERANCE_STEPS",
    "SIMPLIFY_STEPS",
    "Route",
    "corridor",
    "lead_points",
    "simplify",
]

LEAD_S = (
    3.0  # the pursuit point lies this many seconds of driving ahead: past the next report at 0.5 Hz and up
)
LEAD_STEPS = 2  # ... and never nearer than this many planner steps (the escape runs' own look-ahead)
CORRIDOR_STEPS = 4.0  # a unit reported farther than this many steps off its route ...
CORRIDOR_MIN_M = 25.0  # ... and this many metres (8 sigma of a 3 m GPS fix) has left it: re-chosen
SIMPLIFY_STEPS = 0.05  # the legs of a descent route stay within this many steps of the simulated descent
PURSUIT_TOLERANCE_STEPS = 0.5  # the chord to the pursuit point stays within this many steps of the route
MAX_LEAD_POINTS = 256


class Route(StrEnum):
    """What the route a unit follows is (the direction's ``route``)."""

    NONE = ""  # no route yet: plain descent while one is computed (``deliberating``)
    DESCENT = "descent"  # the foreseen steepest descent: it arrives, and nothing is clearly cheaper
    LOWER_EXPOSURE = "lower_exposure"  # a route round the threats, chosen because it is clearly cheaper
    AROUND_TRAP = "around_trap"  # descent would be trapped: a route round the trap, chosen before meeting it
    ESCAPE = "escape"  # a way out of a trap met on the way (a strategy of ``core.escape_strategies``)
    LEAVE = "leave"  # the shortest way out of a threat core or keep-out zone the unit is in

    escaping: bool  # set on each member below: the direction's status is ``escaping``
    words: str


_WORDS = {
    Route.NONE: "",
    Route.DESCENT: "",
    Route.LOWER_EXPOSURE: "route chosen for lower exposure",
    Route.AROUND_TRAP: "route round a trap ahead",
    Route.ESCAPE: "escaping a trap",
    Route.LEAVE: "leaving",
}
for _route in Route:
    _route.escaping = _route in (Route.AROUND_TRAP, Route.ESCAPE, Route.LEAVE)
    _route.words = _WORDS[_route]


def corridor(step: float) -> float:
    """How far off its route, in metres, a unit may report before the route is chosen again."""
    return max(CORRIDOR_STEPS * step, CORRIDOR_MIN_M)


def lead_points(step: float, speed_mps: float) -> int:
    """The pursuit point's distance ahead, in route points (``step`` apart), for a unit at ``speed_mps``."""
    if not (step > 0.0 and math.isfinite(speed_mps) and speed_mps > 0.0):
        return LEAD_STEPS
    return max(LEAD_STEPS, min(math.ceil(LEAD_S * speed_mps / step - 1e-9), MAX_LEAD_POINTS))


def simplify(path: np.ndarray, tolerance: float) -> np.ndarray:
    """The corners of ``path`` ``(K, 2)``: Douglas-Peucker, no point farther than ``tolerance`` from the legs.

    The first and last points are always kept.
    """
    pts = np.ascontiguousarray(path, dtype=np.float64).reshape(-1, 2)
    if len(pts) <= 2:
        return pts.copy()
    keep = _douglas_peucker(pts, float(tolerance))
    return np.asarray(pts[keep])


@numba.njit(cache=True, nogil=True)
def _douglas_peucker(pts: np.ndarray, tol: float) -> np.ndarray:  # pragma: no cover - compiled
    n = pts.shape[0]
    keep = np.zeros(n, dtype=np.bool_)
    keep[0] = True
    keep[n - 1] = True
    stack = np.empty((n, 2), dtype=np.int64)  # each pair of kept indices is pushed at most once
    top = 0
    stack[0, 0] = 0
    stack[0, 1] = n - 1
    top = 1
    while top > 0:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        if b - a < 2:
            continue
        ax, ay = pts[a, 0], pts[a, 1]
        dx, dy = pts[b, 0] - ax, pts[b, 1] - ay
        norm = math.hypot(dx, dy)
        worst = -1.0
        at = a
        for i in range(a + 1, b):
            px, py = pts[i, 0] - ax, pts[i, 1] - ay
            if norm > 0.0:
                d = abs(px * dy - py * dx) / norm
            else:
                d = math.hypot(px, py)
            if d > worst:
                worst = d
                at = i
        if worst > tol:
            keep[at] = True
            stack[top, 0] = a
            stack[top, 1] = at
            stack[top + 1, 0] = at
            stack[top + 1, 1] = b
            top += 2
    return keep
