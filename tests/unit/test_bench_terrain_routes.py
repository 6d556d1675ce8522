"""``pfp bench terrain_routes``: its independent checks can fail, and its figures come from real plans."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.terrain_routes import _ground_slope_deg, _reachable, _steepest, _summary
from pfp_service.terrain.grid import TerrainGrid

pytestmark = pytest.mark.unit


def _ramp(deg: float) -> TerrainGrid:
    x = np.arange(0.0, 1000.0 + 1e-9, 10.0)
    z = np.tile(np.tan(np.radians(deg)) * x, (len(x), 1))  # rising to the east
    return TerrainGrid(0.0, 0.0, 10.0, z)


def test_the_slope_and_grade_are_measured_from_the_heights():
    g = _ramp(20.0)
    slope = _ground_slope_deg(g)
    ground, grade = _steepest(g, slope, [(100.0, 500.0), (900.0, 500.0)])
    assert ground == pytest.approx(20.0, abs=0.01)
    assert grade == pytest.approx(20.0, abs=0.01)
    ground, grade = _steepest(g, slope, [(500.0, 100.0), (500.0, 900.0)])  # across the slope: flat going
    assert ground == pytest.approx(20.0, abs=0.01) and grade == pytest.approx(0.0, abs=1e-6)
    assert not _reachable(g, slope, 15.0, (100.0, 500.0), (900.0, 500.0))
    assert _reachable(g, slope, 25.0, (100.0, 500.0), (900.0, 500.0))


def test_the_summary_flags_a_plan_more_exposed_than_the_blind_one():
    row = {"seed": 0, "reachable": True, "status": "reached", "steepest_ground_deg": 31.0, "exposure": 5.0}
    doc = {
        "limit_deg": 30.0,
        "rows": [
            {**row, "blind_reported": 4.0, "blind_masked": 1.0, "optimal_exposure": 2.0, "j_ratio": 1.2}
        ],
    }
    s = _summary(doc)
    assert s["over_limit"] == [0] and s["worse_than_reported"] == [0] and s["worse_than_masked"] == [0]
    assert s["j_p90"] == pytest.approx(1.2)
