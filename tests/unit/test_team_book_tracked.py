"""The team book's leads' tracks, looked at only when a unit may have moved (``TeamBook.where``), are the tracks looked at every ``judge``.

A wave goes out a share an ``apply`` with no report between its shares, and
``_track`` then skips every team.  Seeded runs of reports (leads', followers'
and outsiders'), staleness, records forgotten, teams put and removed, and
judges with nothing written between them: a book keyed on the units' book
must keep the very tracks of a book without the key.
"""

from __future__ import annotations

import copy
import random

import pytest

from pfp_service.wire import UnitState
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.events import StateReported
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.team_book import TeamBook
from pfp_service.world.units import PhaseError, Units
from pfp_service.world.world import World, WorldSettings

pytestmark = pytest.mark.unit

IDS = [f"u{k}" for k in range(24)]


def _team(rng: random.Random) -> TeamUpdate:
    lead, *follow = rng.sample(IDS, 4)
    return TeamUpdate(lead=lead, follow=follow, corridor_m=rng.choice([16.0, 30.0]))


@pytest.mark.parametrize("seed", range(6))
def test_a_keyed_book_tracks_as_one_that_looks_every_judge(seed: int) -> None:
    rng = random.Random(seed)
    book = Units()
    keyed, plain = TeamBook(seen=lambda: book.version), TeamBook()
    at: dict[str, tuple[float, float]] = {}
    skipped = longest = 0
    try:
        for step in range(1200):
            what, uid = rng.random(), rng.choice(IDS)
            rec = book.records.get(uid)
            try:
                if rec is None or what < 0.45:
                    rec = rec or book.add(uid, True, float(step), reported=True)
                    x, y = at.get(uid, (rng.uniform(0, 100), rng.uniform(0, 100)))
                    at[uid] = (x + rng.choice([0.0, 0.5, 3.0, 9.0]), y + rng.uniform(-2.0, 2.0))
                    book.reported(rec, at[uid], None, None, float(step), 1.0)
                elif what < 0.5:
                    book.go_stale(rec, float(step))
                elif what < 0.51:
                    book.forget(rec)
                elif what < 0.53:
                    tid = f"t{rng.randrange(3)}"
                    if tid in keyed.teams and rng.random() < 0.5:
                        assert keyed.remove(tid) == plain.remove(tid)
                    else:
                        team = _team(rng)
                        assert (keyed.put(tid, team) is None) == (plain.put(tid, team) is None)
                # else: nothing written, as between a wave's shares
            except PhaseError:
                pass
            before = keyed._leads.key
            keyed.judge([], book.records)
            plain.judge([], book.records)
            skipped += before is not None and before == keyed._leads.key
            assert keyed.tracks == plain.tracks
            longest = max([longest, *map(len, plain.tracks.values())])
    except AssertionError:
        print(f"seed {seed}, step {step}")
        raise
    assert skipped > 50  # the key did skip the look, not only agree
    assert longest >= 3  # leads moved and were tracked


def test_a_copied_world_keys_on_its_own_book() -> None:
    """A world deep-copied (a one-pass comparison's twin) keys its caches on its own units, not the original's."""
    w = World(WorldSettings(dispersion=DispersionSettings(enabled=True)))
    w.apply([StateReported("a", UnitState(position=(0.0, 0.0), seq=0))], 0.0)
    twin = copy.deepcopy(w)
    key = w.teams.where()
    twin.apply([StateReported("a", UnitState(position=(5.0, 0.0), seq=1))], 1.0)
    assert w.teams.where() == key
    assert twin.teams.where() != key
