"""Planner parameters and the scale-free rule that fills in the ones not given.

The rule (also in docs/algorithm.md, "Scale-free defaults"):

* ``D0 = ||goal - start||``; ``s_min`` = the narrowest standard deviation of
  any threat, ``sqrt(lambda_min(Omega))``; ``s_j`` = threat j's spread
  ``det(Omega_j)^(1/4)``.
* ``step = clamp(min(D0 / 150, s_min / 4), D0 / 3000, D0 / 20)``: fine enough to
  resolve the narrowest threat, coarse enough that a path is never more than a
  few thousand steps.
* ``tolerance = 0.75 step``: a straight approach ends within half a step of the
  goal, so this always arrives, and it never sits on the knife edge of a
  whole number of steps (the paper pairs 0.1 and 0.1; give both to match it).
* ``max_iter = clamp(ceil(8 D0 / step), 300, 1_000_000)``: room for a path
  eight times the straight line before giving up.  The upper bound only
  matters for an explicit tiny step (the derived step gives at most 24 000);
  an explicit ``max_iter`` is taken as given.
* ``delta = 0.15 D0 median_j(L_j / s_j)``, where ``L_j`` is threat j's peak
  level (its weight under ``peak`` intensity, weight times peak density under
  ``density``).  This sets the goal's pull at the start, ``2 delta / D0``, to
  about half the steepest flank of a typical threat, so the goal draws the unit
  on but never pushes it through a threat's core.  With no threats, 1.

``escape`` (default ``auto``) says what the stepper does when plain descent
is trapped: ``none`` reports ``trapped``; ``auto`` escalates through the
strategies (``core.escape``); any other value is one strategy's name, and the
choices are the names in ``options.ESCAPES``, which the registry ``escape_strategies.STRATEGIES``
implements name for name.
``auto`` also looks ahead for traps when a goal is set (``core.foresight``).
``seed`` seeds the ``random`` escape (with the stepper's ``unit_key``).

Every quantity is a length ratio or a dimensionless level, so a scenario scaled
by any factor resolves to the same path, scaled.

``resolve`` is total: whatever finite numbers it is given, it returns
parameters and never raises.  A start-goal distance too small for its
hundred-and-fiftieth to be a normal float (a goal 5e-324 m away) resolves as
if it were ``SCALE_FLOOR``, so the unit is within tolerance: arrived.  A step
too fine for ``8 D0 / step`` to be a number gets ``MAX_ITER_DERIVED``, and a
derived delta is kept within ``constraints.DELTA_MIN``..``DELTA_MAX``.  What
the planner cannot plan is refused before it gets here, by the validators
(``constraints``); these floors only keep the arithmetic finite.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal, NamedTuple

from pfp_service.constraints import DELTA_MAX, DELTA_MIN, reach_problem
from pfp_service.core.options import ESCAPES, Intensity

if TYPE_CHECKING:  # at run time only its instances' methods: the compiled field stays unimported
    from pfp_service.core.threat import Threat

__all__ = [
    "ESCAPES",
    "MAX_ITER_DERIVED",
    "SCALE_FLOOR",
    "Escape",
    "FieldStats",
    "PlannerParams",
    "Resolved",
    "field_stats",
    "reach",
    "resolve",
]

MAX_ITER_DERIVED = 1_000_000
SCALE_FLOOR = 1e-150  # the smallest start-goal distance derived from: its square is still a normal float

# At run time a real Literal, so msgspec-decoded configs and scenarios refuse
# an unknown escape and the JSON schemas list the choices; a type checker
# cannot read a Literal built from a registry, so to it this is a string.
if TYPE_CHECKING:
    Escape = str
else:
    Escape = Literal[ESCAPES]


@dataclass(frozen=True, slots=True)
class PlannerParams:
    """What a user may set; ``None`` means "derive it" (see module docstring)."""

    delta: float | None = None
    step: float | None = None
    max_iter: int | None = None
    tolerance: float | None = None
    intensity: Intensity = "peak"
    escape: Escape = "auto"
    trap_window: int = 20
    progress_window: int = 200
    seed: int = 0

    def merged(self, **overrides: object) -> PlannerParams:
        """A copy with every non-``None`` override applied."""
        return replace(self, **{k: v for k, v in overrides.items() if v is not None})  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True)
class Resolved:
    """Concrete parameters for one start-goal pair."""

    delta: float
    step: float
    max_iter: int
    tolerance: float
    intensity: Intensity
    escape: Escape
    trap_window: int
    progress_window: int
    seed: int


def _peak_level(t: Threat, intensity: Intensity) -> float:
    return t.weight if intensity == "peak" else t.weight * t.peak_density()


class FieldStats(NamedTuple):
    """What ``resolve`` needs of a threat set, whatever the start and goal: compute once per set."""

    min_sigma: float  # the narrowest standard deviation, metres (inf without threats)
    median_ratio: dict[
        str, float | None
    ]  # by intensity: median peak level / spread (None: no weighted threat)


def field_stats(threats: tuple[Threat, ...] | list[Threat]) -> FieldStats:
    """``resolve``'s threat-set figures, so a goal storm pays O(threats) once, not per goal."""
    spreads = [t.spread() for t in threats]
    s_min = min((t.min_sigma() for t in threats), default=math.inf)
    medians: dict[str, float | None] = {}
    for intensity in ("peak", "density"):
        ratios = [_peak_level(t, intensity) / s for t, s in zip(threats, spreads) if t.weight > 0]
        medians[intensity] = statistics.median(ratios) if ratios else None
    return FieldStats(s_min, medians)


def resolve(
    params: PlannerParams,
    start: tuple[float, float],
    goal: tuple[float, float],
    threats: tuple[Threat, ...] | list[Threat] = (),
    stats: FieldStats | None = None,
) -> Resolved:
    """Fill in what ``params`` leaves open for this start, goal and threat set.

    ``stats`` is ``field_stats(threats)``, when the caller keeps it for many goals.
    """
    d0 = math.hypot(goal[0] - start[0], goal[1] - start[1])
    scale = max(d0, SCALE_FLOOR) if d0 > 0 else 1.0
    if stats is None:
        stats = field_stats(threats)
    s_min = stats.min_sigma  # resolve the narrowest axis
    step = params.step
    if step is None:
        step = min(scale / 150.0, s_min / 4.0)
        step = min(max(step, scale / 3000.0), scale / 20.0)
    tolerance = params.tolerance if params.tolerance is not None else 0.75 * step
    max_iter = params.max_iter
    if max_iter is None:
        need = 8.0 * scale / step if step > 0 else math.inf
        max_iter = max(300, math.ceil(need)) if need < MAX_ITER_DERIVED else MAX_ITER_DERIVED
    delta = params.delta
    if delta is None:
        median = stats.median_ratio[params.intensity]
        delta = 0.15 * scale * median if median is not None else 1.0
        delta = min(max(delta, DELTA_MIN), DELTA_MAX)  # a threat of weight 1e-300 leaves the goal a pull
    return Resolved(
        delta=float(delta),
        step=float(step),
        max_iter=int(max_iter),
        tolerance=float(tolerance),
        intensity=params.intensity,
        escape=params.escape,
        trap_window=params.trap_window,
        progress_window=params.progress_window,
        seed=params.seed,
    )


def reach(params: PlannerParams, start: tuple[float, float], goal: tuple[float, float]) -> str | None:
    """Why a step the caller gave cannot carry a plan from ``start`` to ``goal`` (``None``: it can).

    Only a given step under the derived ``max_iter`` is judged
    (``constraints.reach_problem``): a derived step always reaches, and an
    explicit ``max_iter`` is a cap the caller asked for, so a plan that stops
    there is an honest ``max_iter``.
    """
    if params.step is None or params.max_iter is not None:
        return None
    r = resolve(params, start, goal)
    return reach_problem(math.hypot(goal[0] - start[0], goal[1] - start[1]), r.step, r.max_iter, r.tolerance)
