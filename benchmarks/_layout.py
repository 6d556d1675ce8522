"""The field and the fleet of ``pfp bench service`` (and of ``bench._deliberation``, in process).

Units on the west edge with goals on the east edge, threats in the middle
facing west: traps for plain descent.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["AREA_M", "layout"]

AREA_M = 2000.0


def layout(units: int, threats: int, seed: int) -> dict[str, Any]:
    """Units on the west edge with goals on the east edge, threats in the middle facing west (traps)."""
    from pfp_service.wire import ThreatUpdate

    rng = np.random.default_rng(seed)
    starts = np.column_stack([rng.uniform(0, 0.1, units + 1), rng.uniform(0.05, 0.95, units + 1)]) * AREA_M
    goals = np.column_stack([rng.uniform(0.9, 1.0, units + 1), rng.uniform(0.05, 0.95, units + 1)]) * AREA_M
    field = []
    for j in range(threats):
        xy = (float(rng.uniform(0.25, 0.75) * AREA_M), float(rng.uniform(0.0, 1.0) * AREA_M))
        facing = float((270.0 + rng.uniform(-45, 45)) % 360)
        field.append(
            (
                f"t{j}",
                ThreatUpdate(position=xy, facing_deg=facing, sigma_range=40.0, sigma_lateral=28.0, skew=2.0),
            )
        )
    return {
        "starts": [(float(x), float(y)) for x, y in starts],  # the last one is the bystander's
        "goals": [(float(x), float(y)) for x, y in goals],
        "threats": field,
    }
