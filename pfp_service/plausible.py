"""Plausibility: numbers that are valid but whose scale looks like a unit mistake, said as warnings.

A file can be right by the schema and still wrong by a factor of a thousand:
a weapon's reach in kilometres where metres are meant, a position in degrees
written as metres.  The planner plans it all the same (these are warnings,
never errors); ``pfp plan`` and ``pfp inject --check`` print each on stderr
so a person looks twice.  Pure values in and out.

The rules, for a start-goal distance ``D0``:

* a threat spread (``sigma_range``, ``sigma_lateral``) over ``SPREAD_MAX_D0``
  times ``D0`` and over ``SPREAD_MAX_M``: a whole battlefield under one
  threat (kilometres written as metres?);
* a threat spread under ``SPREAD_MIN_M`` (a centimetre) on a route over a
  kilometre: a threat no step of the planner can see;
* with no origin, a start and goal that both look like degrees
  (``|x| <= 180``, ``|y| <= 90``) and lie under ``DEGREES_D0_M`` apart:
  latitude and longitude written as metres.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

__all__ = ["DEGREES_D0_M", "SPREAD_MAX_D0", "SPREAD_MAX_M", "SPREAD_MIN_M", "warnings"]

SPREAD_MAX_D0 = 20.0
SPREAD_MAX_M = 50_000.0
SPREAD_MIN_M = 0.01
DEGREES_D0_M = 5.0


def warnings(
    start: tuple[float, float],
    goal: tuple[float, float],
    spreads: Iterable[tuple[str, float, float]],
    has_origin: bool,
) -> list[str]:
    """What looks like a unit mistake: one line each.

    Args:
        start, goal: metres.
        spreads: ``(threat id, sigma_range, sigma_lateral)`` in metres.
        has_origin: the file has an origin (its positions may be lat/lon).
    """
    out: list[str] = []
    d0 = math.dist(start, goal)
    if (
        not has_origin
        and 0.0 < d0 < DEGREES_D0_M
        and all(abs(p[0]) <= 180.0 and abs(p[1]) <= 90.0 for p in (start, goal))
        and any(abs(c) > 1.0 and c != round(c) for c in (*start, *goal))
    ):
        out.append(
            f"start {list(start)} and goal {list(goal)} are {d0:.3g} m apart and look like degrees: "
            "positions are metres; for latitude and longitude give an origin and {lat, lon}"
        )
    for tid, sr, sl in spreads:
        widest, narrowest = max(sr, sl), min(sr, sl)
        if widest > SPREAD_MAX_M and widest > SPREAD_MAX_D0 * d0:
            out.append(
                f"threat {tid}: a spread of {widest:,.0f} m covers {widest / max(d0, 1e-9):,.0f} times "
                "the route: kilometres written as metres?"
            )
        elif narrowest < SPREAD_MIN_M and d0 > 1000.0:
            out.append(
                f"threat {tid}: a spread of {narrowest:g} m on a {d0:,.0f} m route: metres written as kilometres?"
            )
    return out
