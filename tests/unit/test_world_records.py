"""The world's records (world/world_records.py): units and threats, the counts kept with them, the field."""

from __future__ import annotations

import pytest

from pfp_service.core import Stepper
from pfp_service.wire import DirectionStatus, Goal, ThreatUpdate
from pfp_service.world.events import Job
from pfp_service.world.world_records import Records, ThreatRecord

pytestmark = pytest.mark.unit


def _threat(tid: str, x: float, expires: float | None = None) -> ThreatRecord:
    u = ThreatUpdate(position=(x, 0.0), sigma_range=1.0, sigma_lateral=0.7)
    return ThreatRecord(u, u.to_threat(tid), expires)


def _job(recs: Records, unit: str) -> Job:
    rec = recs.units[unit]
    job = Job(unit, rec.token(), "foresee", None, None, 0.0)  # type: ignore[arg-type]
    recs.asked(rec, job)
    return job


def test_a_unit_made_by_anything_but_a_report_is_stale_until_it_reports():
    r = Records()
    heard, told = r.add("a", True, 0.0, reported=True), r.add("b", True, 0.0, reported=False)
    assert not heard.stale and told.stale and told.stale_since == 0.0 and r.stale == 1
    assert not told.live()  # never reported: no position, no direction
    r.heard(told, (1.0, 2.0), 7, "ugv", 3.0)
    assert not told.stale and r.stale == 0 and told.live() and told.kind == "ugv" and told.seq == 7


def test_stale_and_forgotten_keep_the_count():
    r = Records()
    rec = r.add("a", True, 0.0, reported=True)
    assert not r.go_stale(rec, 1.0)  # never reported where it is: nothing to mark
    r.heard(rec, (0.0, 0.0), 1, None, 1.0)
    assert r.go_stale(rec, 5.0) and not r.go_stale(rec, 6.0) and r.stale == 1
    assert not r.forgettable(rec, 7.0, 10.0) and r.forgettable(rec, 15.0, 10.0)
    assert not r.forgettable(rec, 1e9, None)  # never forgotten
    r.forget(rec)
    assert r.units == {} and r.stale == 0


def test_a_report_answers_the_push_and_clears_the_token_gone():
    r = Records()
    rec = r.add("a", True, 0.0, reported=True)
    rec.token_gone_since, rec.push = 1.0, object()  # type: ignore[assignment]
    r.heard(rec, (0.0, 0.0), None, None, 2.0)
    assert rec.token_gone_since is None and rec.push is None and rec.last_seen == 2.0


def test_dropping_a_mission_starts_an_epoch_and_supersedes_the_job():
    r = Records()
    rec = r.add("a", True, 0.0, reported=True)
    rec.goal, rec.last_status, rec.last_reason = Goal(position=(5.0, 5.0)), DirectionStatus.EN_ROUTE, "x"
    rec.stepper = Stepper((0.0, 0.0), (5.0, 5.0), _resolved())
    job = _job(r, "a")
    assert r.deliberating == 1 and rec.token() == (0, rec.stepper.version)
    r.drop_mission(rec)
    assert r.superseded == [job] and not job.cancelled and rec.job is None and r.deliberating == 0
    assert rec.goal is None and rec.stepper is None and rec.last_status is None and rec.last_reason == ""
    assert rec.epoch == 1 and rec.token() == (1, -1)


def test_an_answered_job_is_counted_off_once():
    r = Records()
    r.add("a", True, 0.0, reported=True)
    _job(r, "a")
    assert r.answered(r.units["a"]) == "foresee" and r.deliberating == 0
    assert r.supersede(r.units["a"]) is None and r.deliberating == 0


def test_handing_a_unit_over_keeps_its_mission_not_its_stepper():
    r = Records()
    rec = r.add("a", True, 0.0, reported=True)
    rec.shared = (Goal(position=(1.0, 1.0)), (0.0, 0.0), _resolved())
    rec.stepper = Stepper((0.0, 0.0), (1.0, 1.0), _resolved())
    r.hand_over(rec)
    assert not rec.owned and rec.stepper is None and rec.shared is not None
    assert r.counts()["units_owned"] == 0 and r.counts()["units"] == 1


def test_the_field_is_rebuilt_only_when_the_threats_change():
    r = Records("density")
    assert len(r.field) == 0
    r.put_threat("t1", _threat("t1", 1.0))
    f1 = r.field
    assert len(f1) == 1 and r.field is f1  # cached while the threats stand
    old = r.put_threat("t1", _threat("t1", 2.0))
    assert old is not None and old.update.position == (1.0, 0.0)
    assert r.field is not f1 and r.field.threats[0].xi[0] == 2.0
    assert r.remove_threat("t1") is not None and len(r.field) == 0
    assert r.remove_threat("t1") is None


def test_a_threat_expires_only_if_its_ttl_has_run_out():
    r = Records()
    r.put_threat("t", _threat("t", 0.0, expires=10.0))
    assert r.expire("t", 9.0) is None and "t" in r.threats
    r.put_threat("t", _threat("t", 0.0, expires=20.0))  # put again: the old timer finds it fresh
    assert r.expire("t", 10.0) is None
    assert r.expire("t", 20.0) is not None and r.threats == {}
    r.put_threat("forever", _threat("forever", 0.0))
    assert r.expire("forever", 1e12) is None


def _resolved():
    from pfp_service.core import PlannerParams, resolve

    return resolve(PlannerParams(), (0.0, 0.0), (5.0, 5.0), ())
