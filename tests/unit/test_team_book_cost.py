"""The team book's shortcuts (issue 33's cost) say what the straightforward computation says, on seeded inputs.

``TeamBook.dispersed`` is kept per unit until the teams change, ``team_leads.rearmost`` is one pass
without a key call, and ``TeamBook._line`` hands back its kept polyline while the track has not grown:
each is compared here with the plain computation it replaced, so that a stale cache or a changed tie
fails.  Directions and reasons are unchanged on a seeded march (``benchmarks/_march_world.py``'s hash).
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.wire import Goal
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.polyline import Polyline
from pfp_service.world.team_book import TeamBook
from pfp_service.world.team_leads import rearmost
from pfp_service.world.units import UnitRecord

pytestmark = pytest.mark.unit

SEEDS = range(20)


def _plain_dispersed(book: TeamBook, unit: str) -> tuple[str, float] | None:
    """What ``dispersed`` said before it was kept: the first of the unit's teams that sets a separation."""
    for tid, team in book.teams.items():
        if unit in team.units() and team.separation_m is not None:
            return tid, team.separation_m
    return None


@pytest.mark.parametrize("seed", SEEDS)
def test_dispersed_kept_between_team_changes_is_what_the_teams_say(seed: int) -> None:
    rng = random.Random(seed)
    print(f"seed {seed}")
    units = [f"u{i}" for i in range(24)]
    book = TeamBook()
    for _ in range(60):
        tid = f"t{rng.randrange(6)}"
        if tid in book.teams and rng.random() < 0.3:
            book.remove(tid)
        else:
            free = [u for u in units if not any(u in t.units() for k, t in book.teams.items() if k != tid)]
            if len(free) < 2:
                continue
            members = rng.sample(free, rng.randint(2, min(4, len(free))))
            sep = rng.choice([None, 5.0, 20.0, 50.0])
            book.put(tid, TeamUpdate(members=members, separation_m=sep))
        for u in rng.sample(units + ["nobody"], 10):  # asked in any order, some twice, some never
            assert book.dispersed(u) == _plain_dispersed(book, u), (seed, u)


def _record(rng: random.Random, k: int) -> UnitRecord:
    r = UnitRecord(id=f"f{k}", key=k, position=rng.choice([None, (rng.random(), rng.random())]))
    r.stale = rng.random() < 0.2
    r.goal = rng.choice([None, Goal(position=(1.0, 2.0))])
    r.last_distance = rng.choice([None, 0.0, 5.0, 5.0, rng.uniform(0.0, 10.0)])  # ties on purpose
    return r


@pytest.mark.parametrize("seed", SEEDS)
def test_rearmost_in_one_pass_is_max_by_its_key_first_of_equals(seed: int) -> None:
    rng = random.Random(seed)
    print(f"seed {seed}")
    for _ in range(200):
        recs = {f"f{k}": _record(rng, k) for k in range(rng.randint(0, 5))}
        follow = [f for f in recs if rng.random() < 0.9] + ["missing"]
        live = [
            r for f in follow if (r := recs.get(f)) is not None and r.position is not None and not r.stale
        ]
        want = max(live, key=lambda r: (r.goal is not None, r.last_distance or 0.0)) if live else None
        assert rearmost(follow, recs) is want


@pytest.mark.parametrize("seed", SEEDS)
def test_a_track_s_polyline_asked_again_unchanged_is_the_track_s_polyline(seed: int) -> None:
    rng = np.random.default_rng(seed)
    print(f"seed {seed}")
    book = TeamBook()
    book.put("g", TeamUpdate(lead="l", follow=["a", "b"]))
    for _ in range(40):
        if rng.random() < 0.1:  # trimmed: another list
            book.tracks["g"] = list(book.tracks["g"][rng.integers(0, 3) :])
        book.tracks["g"].extend(map(tuple, rng.uniform(-100, 100, (int(rng.integers(0, 3)), 2)).tolist()))
        want = Polyline(book.tracks["g"])
        for _follower in range(int(rng.integers(1, 4))):  # each follower asks in a judge
            got = book._line("g")
            for name in ("pts", "ab", "seg", "sq", "cum"):
                np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
