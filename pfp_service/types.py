"""Constrained value types shared by scenario files and wire messages.

Each is an ``Annotated`` alias that msgspec checks while decoding, so a bad
value fails with its field path.  "Finite" is a bound of ±1e9: NaN and
infinities fail it, and so does anything no map of this planet needs.
"""

from __future__ import annotations

from typing import Annotated

from msgspec import Meta

from pfp_service.errors import FINITE_LIMIT

__all__ = ["Finite", "Id", "Iterations", "NonNegative", "Point", "Positive", "Skew", "StepIndex", "Weight"]

Finite = Annotated[float, Meta(ge=-FINITE_LIMIT, le=FINITE_LIMIT)]
Positive = Annotated[float, Meta(gt=0.0, le=FINITE_LIMIT)]
NonNegative = Annotated[float, Meta(ge=0.0, le=FINITE_LIMIT)]
Skew = Annotated[float, Meta(ge=0.0, le=1000.0)]
Weight = Annotated[float, Meta(ge=0.0, le=1e6)]
StepIndex = Annotated[int, Meta(ge=0, le=10_000_000)]
Iterations = Annotated[int, Meta(ge=1, le=10_000_000)]
Point = tuple[Finite, Finite]
Id = Annotated[str, Meta(pattern=r"^[A-Za-z0-9_-]{1,64}$")]
