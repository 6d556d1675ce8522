"""Readers of where the units are that look at the reported units alone (``neighbours.Reports``) see what a full look sees.

The world notes each report the units' book took; dispersion's fleet index
(``FleetIndex``) and the leads' tracks (``team_tracks.LeadTracks``) then look
at the units reported since they last looked, when the units' version moved
by one a report (reports alone were written) and no team changed.  Seeded
runs of ticks of reports (a unit twice in one, units moved past the kept
k-d tree's slack), with every other write between them (staleness, goals,
records made, forgotten and discarded, teams put and removed, a report the
world did not note): after each, the index must be the one built afresh and
the tracks those a book looking at every lead keeps.  Each fails with the
journal's check broken (reports taken as all that changed when they were not).
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.wire import Goal
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world import neighbours
from pfp_service.world.neighbours import FleetIndex, Reports, fleet_index
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.team_book import TeamBook
from pfp_service.world.units import PhaseError, Units
from tests.unit.test_dispersion_fleet_index import _same

pytestmark = pytest.mark.unit

IDS = [f"u{k}" for k in range(40)]


def _tick(rng: random.Random, book: Units, teams: TeamBook, reports: Reports, at: dict, now: float) -> None:
    """A tick: a few reports noted as the world notes them, and now and then another write."""
    for _ in range(rng.choice([1, 2, 4, 8])):
        uid = rng.choice(IDS)
        rec = book.records.get(uid)
        try:
            if rec is None:
                rec = book.add(uid, True, now, reported=True)
            x, y = at.get(uid, (rng.uniform(0, 600), rng.uniform(0, 600)))
            jump = rng.choice([0.0, 1.0, 5.0, 5.0, 40.0, 300.0])  # 40 and 300 m: past the tree's slack
            at[uid] = (x + rng.uniform(-jump, jump), y + rng.uniform(-jump, jump))
            book.reported(rec, at[uid], None, None, now, 1.0)
            if rng.random() < 0.97:  # else a report the world did not note: the readers must look at all
                reports.note(rec)
        except PhaseError:
            pass
    what = rng.random()
    uid = rng.choice(IDS)
    rec = book.records.get(uid)
    try:
        if rec is None or what < 0.8:
            return
        if what < 0.84:
            book.go_stale(rec, now)
        elif what < 0.88:
            book.set_goal(rec, Goal(position=(rng.uniform(0, 600), rng.uniform(0, 600))), None)
        elif what < 0.9 and rec.goal is not None:
            book.drop_mission(rec)
        elif what < 0.92:
            book.forget(rec)
        elif what < 0.93:
            book.discard(rec)
        else:
            tid = f"t{rng.randrange(5)}"
            if tid in teams.teams and rng.random() < 0.4:
                teams.remove(tid)
            else:
                lead, *follow = rng.sample(IDS, 4)
                sep = rng.choice([None, 20.0, 80.0])
                teams.put(tid, TeamUpdate(lead=lead, follow=follow, separation_m=sep, corridor_m=16.0))
    except PhaseError:
        pass


def _broken(self: Reports, mark: neighbours.Mark | None) -> list | None:
    """``Reports.since`` without its check: the reports since, whatever else was written."""
    if mark is None:
        return None
    return self._recs[mark[1] - self._dropped :]


def _run_index(seed: int) -> int:
    rng = random.Random(seed)
    book = Units()
    reports = Reports(book.seen)
    teams = TeamBook(seen=book.seen, reports=reports)
    settings = DispersionSettings(enabled=True, classes={u: rng.choice(["foot", "wheeled"]) for u in IDS})
    kept = FleetIndex(settings, book.records, teams.dispersed, teams.where)
    took, at = 0, {}
    for step in range(500):
        _tick(rng, book, teams, reports, at, float(step))
        before = reports.since(kept._mark) is not None and kept._kept is not None
        index, recs, row = kept()
        took += before
        plain, precs, prow = fleet_index(book.records, settings, teams.dispersed)
        assert len(recs) == len(precs) and all(a is b for a, b in zip(recs, precs)), (seed, step)
        assert row == prow, (seed, step)
        for name in ("points", "seps", "team", "team_sep", "goals"):
            assert _same(getattr(index, name), getattr(plain, name)), (seed, step, name)
        if len(recs):
            share = np.array(sorted(rng.sample(range(len(recs)), min(len(recs), 6))))
            for a, b in zip(index.near_seps(share), plain.near_seps(share)):
                assert np.array_equal(a, b), (seed, step)
            assert np.array_equal(index.gradients(share), plain.gradients(share)), (seed, step)
    return took


@pytest.mark.parametrize("seed", range(6))
def test_the_index_moved_by_the_reports_alone_is_the_one_built_afresh(seed: int) -> None:
    took = _run_index(seed)
    assert took > 150  # the reports' path was taken, not only the full look


def test_the_index_with_the_reports_check_broken_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(Reports, "since", _broken)
    with pytest.raises(AssertionError):
        for seed in range(6):
            _run_index(seed)


def _run_tracks(seed: int) -> int:
    rng = random.Random(seed)
    book = Units()
    reports = Reports(book.seen)
    keyed, plain = TeamBook(seen=book.seen, reports=reports), TeamBook()
    took, at, longest = 0, {}, 0
    for step in range(800):
        # the same teams in both books: the keyed book's writes copied to the plain one
        had = dict(keyed.teams)
        _tick(rng, book, keyed, reports, at, float(step))
        for tid in had.keys() - keyed.teams.keys():
            plain.remove(tid)
        for tid, team in keyed.teams.items():
            if had.get(tid) is not team:
                assert plain.put(tid, team) is None
        took += reports.since(keyed._leads._mark) is not None and keyed._leads.key is not None
        keyed.judge([], book.records)
        plain.judge([], book.records)
        assert keyed.tracks == plain.tracks, (seed, step)
        longest = max([longest, *map(len, plain.tracks.values())])
    assert longest >= 3  # leads moved and were tracked
    return took


@pytest.mark.parametrize("seed", range(6))
def test_the_leads_looked_at_from_the_reports_track_as_every_lead_looked_at(seed: int) -> None:
    assert _run_tracks(seed) > 200


def test_the_tracks_with_the_reports_check_broken_are_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(Reports, "since", _broken)
    with pytest.raises(AssertionError):
        for seed in range(6):
            _run_tracks(seed)


def test_reports_dropped_from_the_front_send_a_reader_behind_them_to_every_record() -> None:
    book = Units()
    reports = Reports(book.seen)
    rec = book.add("a", True, 0.0, reported=True)
    book.reported(rec, (0.0, 0.0), None, None, 0.0, 1.0)
    mark = reports.mark()
    for k in range(neighbours.REPORTS_KEPT + 1):
        book.reported(rec, (float(k), 0.0), None, None, 0.0, 1.0)
        reports.note(rec)
    assert reports.since(mark) is None  # dropped: unknown
    late = reports.mark()
    book.reported(rec, (1.0, 1.0), None, None, 0.0, 1.0)
    reports.note(rec)
    assert reports.since(late) == [rec]
    book.go_stale(rec, 1.0)
    assert reports.since(late) is None  # something else was written
