"""Constrained value types shared by scenario files and wire messages.

Each is an ``Annotated`` alias that msgspec checks while decoding, so a bad
value fails with its field path.  "Finite" is a bound of ±1e9: NaN and
infinities fail it, and so does anything no map of this planet needs.
``Sigma`` is a threat's spread: at least 1 mm, so its square (and the
determinant of the scale matrix) never underflows to zero; ``check_spreads``
also bounds the ratio of a threat's two spreads, so the rotated matrix stays
invertible in floating point.

``Step``, ``Tolerance`` and ``Delta`` bound what the planner can plan, once,
for wire messages, files and flags alike.  A length below ``LENGTH_MIN_M`` (a
millimetre, the finest ``Sigma``) is refused: at any coordinate within ±1e9 m
it is still about 8,000 units in the last place, so a step moves the unit and
an arrival radius can be met; below it, and at a subnormal, the maths divides
by zero or overflows.  ``Delta`` is the goal's weight against threat weights of
at most 1e6: beyond ``DELTA_MIN``..``DELTA_MAX`` one of the two terms vanishes
in rounding, and the goal gain ``delta / D0**2`` stays a normal float for any
start-goal distance from ``LENGTH_MIN_M`` to the diagonal of the ±1e9 m map.
What needs the start and the goal too is ``reach_problem``: a step that would
need more than ``max_iter`` steps to cover the distance.  A goal closer to its
unit than the tolerance is not a problem: it has arrived.
"""

from __future__ import annotations

import argparse
import math
import typing
from collections.abc import Callable
from typing import Annotated, Any

import msgspec
from msgspec import Meta

from pfp_service.errors import FINITE_LIMIT

__all__ = [
    "DELTA_MAX",
    "DELTA_MIN",
    "LENGTH_MIN_M",
    "SIGMA_MIN_M",
    "SIGMA_RATIO_MAX",
    "Delta",
    "Finite",
    "Id",
    "Iterations",
    "NonNegative",
    "Point",
    "Positive",
    "Sigma",
    "Skew",
    "Step",
    "StepIndex",
    "Tolerance",
    "Weight",
    "check_spreads",
    "flag_type",
    "reach_problem",
]

Finite = Annotated[float, Meta(ge=-FINITE_LIMIT, le=FINITE_LIMIT)]
Positive = Annotated[float, Meta(gt=0.0, le=FINITE_LIMIT)]
NonNegative = Annotated[float, Meta(ge=0.0, le=FINITE_LIMIT)]
SIGMA_MIN_M = 1e-3
Sigma = Annotated[float, Meta(ge=SIGMA_MIN_M, le=FINITE_LIMIT)]
SIGMA_RATIO_MAX = 1e6
LENGTH_MIN_M = SIGMA_MIN_M  # the finest step or arrival radius planned (see the module docstring)
Step = Annotated[float, Meta(ge=LENGTH_MIN_M, le=FINITE_LIMIT)]
Tolerance = Annotated[float, Meta(ge=LENGTH_MIN_M, le=FINITE_LIMIT)]
DELTA_MIN, DELTA_MAX = 1e-9, 1e9
Delta = Annotated[float, Meta(ge=DELTA_MIN, le=DELTA_MAX)]


def check_spreads(sigma_range: float, sigma_lateral: float) -> None:
    """Raise ``ValueError("sigma_lateral: ...")`` when one spread exceeds the other a millionfold.

    Rotating ``diag(sr^2, sl^2)`` loses about ``eps (sr/sl)^2`` of the
    determinant to rounding; past this ratio the scale matrix is numerically singular.
    """
    lo, hi = sorted((sigma_range, sigma_lateral))
    if hi > SIGMA_RATIO_MAX * lo:
        raise ValueError(
            f"sigma_lateral: sigma_range and sigma_lateral must be within a factor {SIGMA_RATIO_MAX:g}"
        )


Skew = Annotated[float, Meta(ge=0.0, le=1000.0)]
Weight = Annotated[float, Meta(ge=0.0, le=1e6)]
StepIndex = Annotated[int, Meta(ge=0, le=10_000_000)]
Iterations = Annotated[int, Meta(ge=1, le=10_000_000)]
Point = tuple[Finite, Finite]
Id = Annotated[str, Meta(pattern=r"^[A-Za-z0-9_-]{1,64}$")]


def reach_problem(distance_m: float, step_m: float, max_iter: int, tolerance_m: float) -> str | None:
    """Why ``max_iter`` steps of ``step_m`` cannot bring a unit ``distance_m`` from its goal within reach.

    Returns:
        The reason, in words a person reads (``None``: it can, or the goal
        is already within ``tolerance_m``: arrived, not a problem).
    """
    numbers = (distance_m, step_m, tolerance_m)
    if not (all(map(math.isfinite, numbers)) and step_m > 0 and tolerance_m >= 0):
        return (
            f"cannot plan {distance_m:g} m with a step of {step_m:g} m and a tolerance of {tolerance_m:g} m"
        )
    if not distance_m > tolerance_m:
        return None
    need = (distance_m - tolerance_m) / step_m
    if need <= max_iter:
        return None
    return (
        f"a step of {step_m:g} m needs {need:.3g} steps to come within {tolerance_m:g} m of a goal "
        f"{distance_m:g} m away, more than max_iter ({max_iter:,})"
    )


def flag_type(constraint: Any, what: str = "a number") -> Callable[[str], Any]:
    """An argparse ``type`` that checks a flag against the same bound as the messages and files.

    ``flag_type(Step)`` takes ``"0.5"`` and refuses ``"1e-9"`` with the bound
    itself: ``must be a finite number >= 0.001 (at most 1e+09), got '1e-9'``.
    """
    base, *metas = typing.get_args(constraint)
    meta = next(m for m in metas if isinstance(m, Meta))
    low = f">= {meta.ge:g}" if meta.ge is not None else f"> {meta.gt:g}"
    bound = f"must be a finite number {low} (at most {meta.le:g})"

    def parse(text: str) -> Any:
        try:
            value = base(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        try:
            return msgspec.convert(value, constraint)
        except msgspec.ValidationError:
            raise argparse.ArgumentTypeError(f"{bound}, got {text!r}") from None

    parse.__name__ = what  # argparse names the type in its own messages
    return parse
