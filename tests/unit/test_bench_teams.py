"""``pfp bench teams``: the same fleet with and without teams, and the teams really judged."""

from __future__ import annotations

import pytest

from benchmarks.teams import measure

pytestmark = pytest.mark.unit


def test_the_teamed_run_is_judged_by_its_teams_and_the_plain_one_is_not():
    plain, teamed = measure(16, 3, False), measure(16, 3, True)
    assert plain["judged"] == 0 and teamed["judged"] > 0
    assert plain["us_per_state"] > 0 and teamed["us_per_state"] > 0


def test_the_terrain_runs_put_each_scenario_threat_as_it_was_built():
    from benchmarks._teams_terrain import _update
    from pfp_service.core import Threat

    for facing, skew in ((30.0, 1.5), (250.0, 0.0), (181.0, 0.7)):
        t = Threat.from_facing((10.0, -20.0), facing, 800.0, 640.0, skew, 1.0, "t1")
        u = _update(t)
        assert u.position == (10.0, -20.0) and abs(u.sigma_range - 800.0) < 1e-6
        assert abs(u.sigma_lateral - 640.0) < 1e-6 and abs(u.skew - skew) < 1e-9
        if skew:  # a symmetric threat faces either way
            assert abs((u.facing_deg - facing + 180.0) % 360.0 - 180.0) < 1e-6
