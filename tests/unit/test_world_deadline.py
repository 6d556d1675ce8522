"""``World.next_deadline``: when the world next needs an ``apply``; and twin conflicts decided in the world.

A driver that applies a ``Tick`` only at the world's deadlines (as the node's
loop does) sends what one ticking on a fixed period sends, at the same
moments or sooner.
"""

from __future__ import annotations

import math

import pytest

from pfp_service.wire import ConflictEvent, Goal, StaleEvent, ThreatUpdate, UnitState
from pfp_service.world.world import (
    GoalSet,
    PeerPlanner,
    StateReported,
    ThreatPut,
    Tick,
    TokenChanged,
    World,
    WorldSettings,
)

pytestmark = pytest.mark.unit


def _state(unit: str, x: float = 0.0, y: float = 0.0) -> StateReported:
    return StateReported(unit, UnitState(position=(x, y)))


def test_an_empty_world_needs_no_tick_and_a_report_needs_one_when_the_unit_may_go_stale():
    w = World(WorldSettings(unit_stale_s=10.0, unit_forget_s=100.0))
    assert w.next_deadline() is None
    w.apply([_state("u")], 1.0)
    assert w.next_deadline() == 11.0  # silent from 1 s on: stale at 11 s
    assert _at_deadlines(w, lambda: w.counts()["units_stale"] == 1) == pytest.approx(11.0)
    assert w.next_deadline() == pytest.approx(111.0)  # stale: forgotten 100 s on
    assert _at_deadlines(w, lambda: w.counts()["units"] == 0) == pytest.approx(111.0)
    assert w.next_deadline() is None


def _at_deadlines(w: World, done) -> float:
    """Tick ``w`` at its deadlines until ``done()``; when (a timer due exactly at a bound looks again a hair later)."""
    for _ in range(3):
        due = w.next_deadline()
        assert due is not None
        w.apply([Tick(due)], due)
        if done():
            return due
    raise AssertionError("not done at the deadlines")


def test_the_earliest_timer_is_the_deadline_a_threat_s_ttl_included():
    w = World(WorldSettings(unit_stale_s=10.0))
    w.apply(
        [ThreatPut("t", ThreatUpdate(position=(5.0, 5.0), sigma_range=1, sigma_lateral=1, ttl_s=3.0))], 0.0
    )
    assert w.next_deadline() == 3.0
    w.apply([_state("u")], 1.0)
    assert w.next_deadline() == 3.0
    w.apply([Tick(3.0)], 3.0)
    assert w.counts()["threats"] == 0 and w.next_deadline() == 11.0


def test_a_wave_owed_its_points_is_due_at_once():
    w = World(WorldSettings())
    units = [f"u{i}" for i in range(100)]  # past WAVE_FIRST: the directions first, the points owed
    w.apply([*(GoalSet(u, Goal(position=(100.0, float(i)))) for i, u in enumerate(units))], 0.0)
    w.apply([_state(u, 0.0, float(i)) for i, u in enumerate(units)], 0.0)
    w.apply([ThreatPut("t", ThreatUpdate(position=(50.0, 50.0), sigma_range=5, sigma_lateral=5))], 0.5)
    assert w.wave_pending() and w.next_deadline() == 0.5  # the last apply's clock: due now
    while w.wave_pending():
        w.apply([Tick(0.6)], 0.6)
    due = w.next_deadline()
    assert due is not None and due > 0.6  # paid: the push re-sends' timers and the silence timers again


def _events(out) -> list[tuple[str, str]]:
    return [(type(e).__name__, getattr(e, "unit", "")) for e in out.events]


def _script() -> dict[float, list]:
    """Units that report, fall silent, lose their token and come back; a threat that expires."""
    threat = ThreatUpdate(position=(30.0, 30.0), sigma_range=2, sigma_lateral=2, ttl_s=7.3)
    return {
        0.0: [GoalSet("a", Goal(position=(50.0, 50.0))), _state("a"), _state("b"), _state("c")],
        1.0: [ThreatPut("t", threat), _state("c", 1.0, 0.0)],
        2.5: [TokenChanged("b", False)],
        4.0: [_state("c", 2.0, 0.0)],
        20.0: [_state("a", 1.0, 1.0)],
    }


def _run(period_s: float | None, until: float = 40.0) -> list[tuple[float, tuple[str, str]]]:
    w = World(WorldSettings(unit_stale_s=5.0, unit_forget_s=12.0, liveliness_debounce_s=1.5))
    script, said, t = _script(), [], 0.0
    moments = sorted(script)
    while t <= until:
        out = w.apply([*script.get(t, []), Tick(t)], t)
        said += [(t, e) for e in _events(out)]
        nxt = [m for m in moments if m > t]
        due = w.next_deadline() if period_s is None else t + period_s
        t = min([*nxt, due if due is not None else math.inf])
        if t == math.inf:
            break
    return said


def test_ticking_at_the_deadlines_says_what_a_fixed_period_says_and_never_later():
    periodic, deadlines = _run(0.05), _run(None)
    assert {e for _, e in periodic} == {e for _, e in deadlines}
    said = {e for _, e in deadlines}
    assert ("StaleEvent", "b") in said and ("ForgottenEvent", "c") in said and ("ReplanEvent", "") in said

    def times(said):
        out: dict[tuple[str, str], list[float]] = {}
        for t, e in said:
            out.setdefault(e, []).append(t)
        return out

    by_period, by_deadline = times(periodic), times(deadlines)
    assert by_period.keys() == by_deadline.keys()
    for e, ts in by_deadline.items():  # each said as often, and each time no later
        assert len(ts) == len(by_period[e]) and all(a <= b + 1e-9 for a, b in zip(ts, by_period[e])), e


def test_a_twin_under_cluster_is_a_conflict_decided_by_the_world_and_never_a_peer():
    w = World(WorldSettings(cluster=True, planner_id="alpha"))
    w.apply([_state("u")], 0.0)
    out = w.apply([PeerPlanner("alpha-1234abcd", True, session="1234abcdef")], 1.0)
    (ev,) = [e for e in out.events if isinstance(e, ConflictEvent)]
    assert ev.other == "alpha-1234abcd" and "session 1234abcdef" in ev.reason and "--planner-id" in ev.reason
    assert w.owns("u") and len(w.shards()) == 16  # never shared with: it is no peer
    assert not w.apply([PeerPlanner("alpha-1234abcd", False, session="1234abcdef")], 2.0).events


def test_another_planner_without_cluster_is_a_conflict_once():
    w = World(WorldSettings(planner_id="alpha"))
    out = w.apply([PeerPlanner("bravo", True)], 0.0)
    (ev,) = out.events
    assert isinstance(ev, ConflictEvent) and ev.other == "bravo" and "both answer every unit" in ev.reason
    assert not w.apply([PeerPlanner("bravo", True)], 0.5).events  # known: said once


def test_a_stale_event_comes_at_a_deadline_not_a_period_later():
    w = World(WorldSettings(unit_stale_s=5.0))
    w.apply([_state("u")], 0.0)
    assert not [e for e in w.apply([Tick(4.999)], 4.999).events if isinstance(e, StaleEvent)]
    for _ in range(3):  # a timer due exactly at the bound looks again a hair later (``liveness``)
        due = w.next_deadline()
        assert due is not None
        stale = [e for e in w.apply([Tick(due)], due).events if isinstance(e, StaleEvent)]
        if stale:
            break
    assert stale and due == pytest.approx(5.0)
