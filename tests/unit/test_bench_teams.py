"""``pfp bench teams``: the same fleet with and without teams, and the teams really judged."""

from __future__ import annotations

import pytest

from benchmarks.teams import measure

pytestmark = pytest.mark.unit


def test_the_teamed_run_is_judged_by_its_teams_and_the_plain_one_is_not():
    plain, teamed = measure(16, 3, False), measure(16, 3, True)
    assert plain["judged"] == 0 and teamed["judged"] > 0
    assert plain["us_per_state"] > 0 and teamed["us_per_state"] > 0
