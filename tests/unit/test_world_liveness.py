"""Liveness (world/liveness.py): silence and a token gone make a unit stale, stale long enough it is forgotten,
and a push is sent again until the unit's next report."""

from __future__ import annotations

import pytest

from pfp_service.wire import Direction, DirectionStatus, ForgottenEvent, StaleEvent, UnitState
from pfp_service.world.events import Outputs, WorldSettings
from pfp_service.world.liveness import Liveness
from pfp_service.world.timers import Timers
from pfp_service.world.units import Units

pytestmark = pytest.mark.unit


def _live(**kw) -> tuple[Liveness, Units, Timers]:
    recs, timers = Units(), Timers()
    return Liveness(WorldSettings(**kw), recs, timers), recs, timers


def _run(live: Liveness, timers: Timers, recs: Units, now: float) -> Outputs:
    """What the unit timers due by ``now`` put out (what the world's tick does for them)."""
    out = Outputs()
    for kind, ident in timers.due(now):
        if ident in recs.records:
            live.due(kind, recs.records[ident], now, out)
    return out


def _report(live: Liveness, recs: Units, uid: str, now: float) -> None:
    rec = recs.records.get(uid) or recs.add(uid, True, now, reported=True)
    live.reported(rec, UnitState(position=(1.0, 2.0), seq=1), now)


def test_a_silent_unit_goes_stale_once_and_a_unit_that_reports_never_does():
    live, recs, timers = _live(unit_stale_s=10.0, unit_forget_s=None)
    _report(live, recs, "quiet", 0.0)
    _report(live, recs, "chatty", 0.0)
    for t in range(1, 25):
        _report(live, recs, "chatty", float(t))
        out = _run(live, timers, recs, float(t))
        stale = [e for e in out.events if isinstance(e, StaleEvent)]
        if t == 11:  # the first tick past 10 s of silence
            assert [e.unit for e in stale] == ["quiet"] and "silent for 11 s" in stale[0].reason
        else:
            assert stale == []
    assert recs.stale == 1 and len(timers) == 1  # chatty's one silence timer, looked at again: never a pile


def test_a_token_gone_makes_a_unit_stale_only_after_the_debounce_unless_it_comes_back():
    live, recs, timers = _live(liveliness_debounce_s=2.0, unit_forget_s=None)
    _report(live, recs, "a", 0.0)
    _report(live, recs, "b", 0.0)
    live.token(recs.records["a"], False, 1.0)
    live.token(recs.records["b"], False, 1.0)
    live.token(recs.records["b"], True, 2.0)  # back within the debounce
    stale = [e for e in _run(live, timers, recs, 3.0).events if isinstance(e, StaleEvent)]
    assert [e.unit for e in stale] == ["a"] and "token" in stale[0].reason


def test_stale_long_enough_is_forgotten_unless_it_reports():
    live, recs, timers = _live(unit_stale_s=1.0, unit_forget_s=5.0)
    _report(live, recs, "gone", 0.0)
    _report(live, recs, "back", 0.0)
    _run(live, timers, recs, 1.5)  # both stale now, forgotten at 6.5 unless ...
    _report(live, recs, "back", 3.0)
    out = _run(live, timers, recs, 6.5)
    forgotten = [e for e in out.events if isinstance(e, ForgottenEvent)]
    assert [e.unit for e in forgotten] == ["gone"] and forgotten[0].stale_s == pytest.approx(5.0)
    assert set(recs.records) == {"back"}


def test_a_unit_never_heard_from_is_forgotten_in_time():
    live, recs, timers = _live(unit_forget_s=5.0)
    live.made(recs.add("told", True, 0.0, reported=False), 0.0)
    gone = [e for e in _run(live, timers, recs, 5.0).events if isinstance(e, ForgottenEvent)]
    assert [e.unit for e in gone] == ["told"] and recs.records == {}


def test_a_push_is_sent_again_until_the_next_report_and_no_more_than_its_retries():
    live, recs, timers = _live(push_retry_s=0.25, push_retries=2, unit_stale_s=1e9)
    _report(live, recs, "a", 0.0)
    _report(live, recs, "b", 0.0)
    d = {u: Direction(unit=u, status=DirectionStatus.EN_ROUTE, vector=(1.0, 0.0)) for u in "ab"}
    live.pushed([d["a"], d["b"]], 0.0)  # answering the reports of this batch: not pushes
    assert live.pushes == 0
    live.pushed([d["a"], d["b"]], 1.0)  # no report asked: pushes
    assert live.pushes == 2
    _report(live, recs, "b", 1.1)  # b answers: its push is done
    again = [x.unit for t in (1.25, 1.5, 1.75, 2.0) for x in _run(live, timers, recs, t).directions]
    assert again == ["a", "a"] and live.pushes_resent == 2
    assert live.counts() == {"pushes": 2, "pushes_resent": 2}


def test_a_wave_s_re_sends_go_a_bounded_number_an_apply_and_every_one_goes():
    from pfp_service.world.liveness import RESEND_LATER_S, RESENDS_PER_APPLY

    live, recs, timers = _live(push_retry_s=0.25, push_retries=1, unit_stale_s=1e9)
    n = 2 * RESENDS_PER_APPLY + 5
    units = [f"u{i:03d}" for i in range(n)]
    for u in units:
        _report(live, recs, u, 0.0)
    live.pushed([Direction(unit=u, status=DirectionStatus.EN_ROUTE, vector=(1.0, 0.0)) for u in units], 1.0)
    sent, t = [], 1.25
    while len(sent) < n:
        assert t < 1.3, "re-sends left behind"
        out = [x.unit for x in _run(live, timers, recs, t).directions]
        assert len(out) <= RESENDS_PER_APPLY  # the tick's puts bounded
        sent += out
        t += RESEND_LATER_S
    assert sorted(sent) == units and live.pushes_resent == n  # each once, as its one retry
