"""Threat cores: the half-maximum regions paths must not enter, and the step they imply."""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Threat, ThreatField, resolve
from pfp_service.core.cores import Cores

pytestmark = pytest.mark.unit


def test_thin_threats_are_resolved_by_their_narrow_axis():
    """A 100 m x 1 m threat: its core is about 2.4 m wide, so no segment may step over it."""
    thin = Threat.from_facing((50.0, 0.0), 0.0, 100.0, 1.0, 0.0, 1.0, "thin")
    assert abs(thin.min_sigma() - 1.0) < 1e-9 and thin.spread() == 10.0
    cores = Cores(ThreatField([thin]))
    assert cores.inside(np.array([[50.0, 0.0]]))[0]
    assert cores.first_hit(np.array([[48.8, 0.0], [51.3, 0.0]])) == "thin"
    p = resolve(PlannerParams(), (0.0, -300.0), (0.0, 300.0), [thin])
    assert p.step <= 0.25 + 1e-12  # a quarter of the narrow sigma, not of the 10 m spread
