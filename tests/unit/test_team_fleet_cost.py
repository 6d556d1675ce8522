"""Dispersion's fleet index keyed in two parts (``neighbours.FleetKey``, ``TeamBook.where``) is the one built afresh.

With the units' part and the teams' part of its key apart, the kept index
takes its rows' teams again while the teams' part stands and its rows are the
very records (``FleetIndex.__call__``), not asking ``team_of`` for each unit.
Seeded runs of every write the units' book and the teams make (as
``test_dispersion_fleet_index``'s): after each, the arrays must be those
``fleet_index`` builds; the teams must have been asked only when the teams or
the records changed; and a ``team_of`` that answers otherwise than its teams
said (the cut broken: reused across a team's change) is caught.
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.world.neighbours import FleetIndex, FleetKey, fleet_index
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.team_book import TeamBook
from pfp_service.world.units import Units
from tests.unit.test_dispersion_fleet_index import IDS, _same, _write

pytestmark = pytest.mark.unit


def _run(seed: int, key_teams: bool = True) -> tuple[int, int]:
    """Seeded writes, the kept index checked against ``fleet_index`` after each; (steps the teams were
    asked, steps in all).  ``key_teams=False``: the key's teams' part never changes (the cut broken)."""
    rng = random.Random(seed)
    book, teams = Units(), TeamBook()
    settings = DispersionSettings(enabled=True, classes={u: rng.choice(["foot", "wheeled"]) for u in IDS})
    asked = [0]

    def team_of(unit: str) -> tuple[str, float] | None:
        asked[0] += 1
        return teams.dispersed(unit)

    kept = FleetIndex(
        settings, book.records, team_of, lambda: FleetKey(book.version, teams.version if key_teams else 0)
    )
    steps_asked = 0
    for step in range(400):
        _write(rng, book, teams, float(step))
        before = asked[0]
        index, recs, row = kept()
        steps_asked += asked[0] > before
        plain, precs, prow = fleet_index(book.records, settings, teams.dispersed)
        assert all(a is b for a, b in zip(recs, precs)) and len(recs) == len(precs), (seed, step)
        assert row == prow
        for name in ("points", "seps", "team", "team_sep", "goals"):
            assert _same(getattr(index, name), getattr(plain, name)), (seed, step, name)
        if len(recs):
            share = np.array(sorted(rng.sample(range(len(recs)), min(len(recs), 5))))
            for a, b in zip(index.near_seps(share), plain.near_seps(share)):
                assert np.array_equal(a, b)
    return steps_asked, 400


@pytest.mark.parametrize("seed", range(6))
def test_the_index_keyed_in_two_parts_is_the_one_built_afresh_and_asks_teams_less(seed: int) -> None:
    asked, steps = _run(seed)
    assert asked < steps * 0.8  # reports alone (about half the writes) did not ask the teams again


def test_a_key_whose_teams_part_misses_a_team_change_is_caught() -> None:
    """The test above fails with the cut broken: teams reused across a team's change differ from a build."""
    with pytest.raises(AssertionError):
        for seed in range(6):
            _run(seed, key_teams=False)
