"""Constrained value types shared by scenario files and wire messages.

Each is an ``Annotated`` alias that msgspec checks while decoding, so a bad
value fails with its field path.  "Finite" is a bound of ±1e9: NaN and
infinities fail it, and so does anything no map of this planet needs.
``Sigma`` is a threat's spread: at least 1 mm, so its square (and the
determinant of the scale matrix) never underflows to zero; ``check_spreads``
also bounds the ratio of a threat's two spreads, so the rotated matrix stays
invertible in floating point.
"""

from __future__ import annotations

from typing import Annotated

from msgspec import Meta

from pfp_service.errors import FINITE_LIMIT

__all__ = [
    "SIGMA_MIN_M",
    "SIGMA_RATIO_MAX",
    "Finite",
    "Id",
    "Iterations",
    "NonNegative",
    "Point",
    "Positive",
    "Sigma",
    "Skew",
    "StepIndex",
    "Weight",
    "check_spreads",
]

Finite = Annotated[float, Meta(ge=-FINITE_LIMIT, le=FINITE_LIMIT)]
Positive = Annotated[float, Meta(gt=0.0, le=FINITE_LIMIT)]
NonNegative = Annotated[float, Meta(ge=0.0, le=FINITE_LIMIT)]
SIGMA_MIN_M = 1e-3
Sigma = Annotated[float, Meta(ge=SIGMA_MIN_M, le=FINITE_LIMIT)]
SIGMA_RATIO_MAX = 1e6


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
