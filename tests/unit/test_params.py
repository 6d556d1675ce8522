"""Parameter resolution: the scale-free derived values and their caps."""

from __future__ import annotations

import pytest

from pfp_service.core import PlannerParams, resolve
from pfp_service.core.params import MAX_ITER_DERIVED

pytestmark = pytest.mark.unit


def test_derived_max_iter_is_capped_explicit_is_kept():
    assert resolve(PlannerParams(step=1e-4), (0, 0), (1e5, 0)).max_iter == MAX_ITER_DERIVED
    assert resolve(PlannerParams(step=1e-4, max_iter=5_000_000), (0, 0), (1e5, 0)).max_iter == 5_000_000
    # the derived step keeps the old rule untouched
    assert resolve(PlannerParams(), (0, 0), (1e5, 0)).max_iter == 1200
