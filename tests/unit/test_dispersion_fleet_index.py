"""Dispersion's fleet index kept between applies (``neighbours.FleetIndex``) is the one built afresh.

The index is kept while the units' book (``Units.version``) and the teams
(``TeamBook.version``) say nothing it is built from changed.  Seeded runs of
every write the book makes (reports, staleness, goals set and dropped,
records made, forgotten and discarded) and of teams put and removed, with
applies between them that write nothing: after each, the kept index must
hold the arrays, rows and records ``fleet_index`` builds, and answer a
share's queries in the very order and numbers a new one does.  When only
positions changed since (a tick's reports), the index is the kept one's with
the reported rows moved (``neighbours._moved``): the same arrays again.
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.wire import Goal
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.neighbours import FleetIndex, fleet_index
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.team_book import TeamBook
from pfp_service.world.units import PhaseError, Units

pytestmark = pytest.mark.unit

IDS = [f"u{k}" for k in range(40)]


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def _write(rng: random.Random, book: Units, teams: TeamBook, now: float) -> str:
    """One write of the book's or the teams' (or none), at random; what it was."""
    recs = book.records
    uid = rng.choice(IDS)
    rec = recs.get(uid)
    what = rng.choice(["report", "report", "stale", "goal", "drop", "forget", "discard", "team", "none"])
    try:
        if rec is None or what == "report":
            rec = rec or book.add(uid, True, now, reported=rng.random() < 0.7)
            pos = (rng.uniform(0, 600), rng.uniform(0, 600))
            book.reported(rec, pos, None, None, now, 1.0)
            return "report"
        if what == "stale":
            book.go_stale(rec, now)
        elif what == "goal":
            book.set_goal(rec, Goal(position=(rng.uniform(0, 600), rng.uniform(0, 600))), None)
        elif what == "drop" and rec.goal is not None:
            book.drop_mission(rec)
        elif what == "forget":
            book.forget(rec)
        elif what == "discard":
            book.discard(rec)
        elif what == "team":
            tid = f"t{rng.randrange(4)}"
            if tid in teams.teams and rng.random() < 0.4:
                teams.remove(tid)
            else:
                members = rng.sample(IDS, 4)
                sep = rng.choice([None, 20.0, 80.0, 1e6])  # 1e6: past TEAM_WIDEST, kept at it
                teams.put(tid, TeamUpdate(members=members, separation_m=sep))  # a clash: refused, no change
    except PhaseError:  # a step the table refuses: whatever it wrote before must count too
        pass
    return what


@pytest.mark.parametrize("seed", range(6))
def test_the_kept_index_is_the_one_built_afresh(seed: int) -> None:
    rng = random.Random(seed)
    book, teams = Units(), TeamBook()
    settings = DispersionSettings(enabled=True, classes={u: rng.choice(["foot", "wheeled"]) for u in IDS})
    kept = FleetIndex(settings, book.records, teams.dispersed, lambda: (book.version, teams.version))
    hits, moved, last = 0, 0, None
    try:
        for step in range(400):
            _write(rng, book, teams, float(step))
            got = kept()
            index, recs, row = got
            hits += got is last
            # rebuilt where only positions changed: the reports' rows moved on the arrays kept (``_moved``)
            moved += last is not None and got is not last and index.goals is last[0].goals
            last = got
            plain, precs, prow = fleet_index(book.records, settings, teams.dispersed)
            assert [r.id for r in recs] == [r.id for r in precs] and all(a is b for a, b in zip(recs, precs))
            assert row == prow
            for name in ("points", "seps", "team", "team_sep", "goals"):
                assert _same(getattr(index, name), getattr(plain, name)), name
            assert index.radius == plain.radius
            if not len(recs):
                continue
            # a share's queries: the kept index was asked others before; it must answer as the new one
            share = np.array(sorted(rng.sample(range(len(recs)), min(len(recs), rng.choice([1, 3, 30])))))
            for a, b in zip(index.near_seps(share), plain.near_seps(share)):
                assert np.array_equal(a, b)
            assert np.array_equal(index.gradients(share), plain.gradients(share))
            some = share[: max(1, len(share) // 2)]  # a later caller's rows among the share's
            for a, b in zip(index.near_seps(some), plain.near_seps(some)):
                assert np.array_equal(a, b)
    except AssertionError:
        print(f"seed {seed}, step {step}")
        raise
    assert hits > 20  # the index was kept, not only rebuilt
    assert moved > 20  # ... and moved by reports, not only built afresh


def test_without_a_version_it_is_built_every_call() -> None:
    book = Units()
    rec = book.add("a", True, 0.0, reported=True)
    book.reported(rec, (0.0, 0.0), None, None, 0.0, 1.0)
    plain = FleetIndex(DispersionSettings(enabled=True), book.records)
    assert plain()[0] is not plain()[0]
