"""The world's deliberation off the loop, geodetic directions, reach and pushes (split from ``test_world``)."""

from __future__ import annotations

import math

import pytest

from pfp_service.core import PlannerParams
from pfp_service.wire import (
    DirectionStatus,
    Goal,
    ReplanEvent,
    ThreatUpdate,
    decode_direction,
    encode,
)
from pfp_service.world.world import (
    Deliberated,
    GoalCancelled,
    GoalSet,
    PeerPlanner,
    ThreatPut,
    ThreatRemoved,
    Tick,
)
from tests.unit.test_world import T, _events, _horseshoe, _one, _state, _world

pytestmark = pytest.mark.unit


# -- deliberation off the loop ------------------------------------------------------
def _deferred(**kw):
    return _world(deliberation="deferred", **kw)


def test_deferred_deliberation_gives_descent_first_then_the_route():
    w = _deferred(planner=PlannerParams(escape="auto"))
    out = w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    d = _one(out, "u")
    assert d.status is DirectionStatus.EN_ROUTE and d.deliberating
    (job,) = out.jobs
    assert w.counts()["deliberating"] == 1
    done = job.run(0.5)
    d = _one(w.apply([done, _state("u", 0, 0)], 0.5), "u")
    assert d.status is DirectionStatus.ESCAPING and not d.deliberating  # the foreseen trap's route
    assert w.counts()["deliberating"] == 0


def test_a_superseded_job_never_overwrites_a_newer_result():
    w = _deferred(planner=PlannerParams(escape="auto"))
    out = w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    (old,) = out.jobs
    # the world changes within the unit's reach before the job lands: a new job is asked, the old one is cancelled
    out = w.apply([ThreatPut("behind", ThreatUpdate(position=(-40, -40), **T))], 0.1)
    assert (
        out.cancelled == [old] and not old.cancelled
    )  # said as an output; the job the world returned is left alone
    (new,) = out.jobs  # the re-direction the change caused asked again, for the new world
    stale_result = old.run(0.3)
    d = _one(w.apply([stale_result, _state("u", 0, 0)], 0.3), "u")
    assert d.deliberating and w.counts()["deliberating"] == 1  # still waiting for the newer one
    d = _one(w.apply([new.run(0.4), _state("u", 0, 0)], 0.4), "u")
    assert d.status is DirectionStatus.ESCAPING and w.counts()["deliberating"] == 0
    # a result for a cancelled goal is dropped too
    out = w.apply([GoalSet("u", Goal(position=(100, 100))), _state("u", 0, 0)], 0.5)
    (job,) = out.jobs
    w.apply([GoalCancelled("u")], 0.6)
    d = _one(w.apply([job.run(0.7), _state("u", 0, 0)], 0.7), "u")
    assert d.status is DirectionStatus.NO_GOAL


def test_a_change_out_of_a_deliberating_units_widened_reach_leaves_its_job_alone():
    w = _deferred(planner=PlannerParams(escape="auto"))
    out = w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    (job,) = out.jobs
    out = w.apply([ThreatPut("far", ThreatUpdate(position=(-500, -500), **T))], 0.1)
    assert not out.cancelled and not out.jobs and not out.directions  # not re-judged: its job stands
    d = _one(w.apply([job.run(0.2), _state("u", 0, 0)], 0.2), "u")
    assert d.status is DirectionStatus.ESCAPING and w.counts()["deliberating"] == 0


def test_a_job_past_its_deadline_is_not_computed_and_the_unit_descends():
    w = _deferred(planner=PlannerParams(escape="auto"), deliberation_budget_s=1.0)
    out = w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    (job,) = out.jobs
    done = job.run(5.0)
    assert done.stepper is None
    out = w.apply([done, _state("u", 0, 0)], 5.0)
    d = _one(out, "u")
    # it descends meanwhile, and the dropped look-ahead is asked again behind the queue
    assert d.status is DirectionStatus.EN_ROUTE and d.deliberating
    (again,) = out.jobs
    assert again.kind == "foresee" and again.deadline == 6.0


def test_deliberated_for_an_unknown_unit_is_ignored():
    w = _deferred()
    assert not w.apply([Deliberated("nobody", (0, 0), None)], 0.0)


def test_deferred_trap_escape_is_searched_off_the_loop():
    """A live unit's look-ahead and its escape are both deliberation (``core.tracking``).

    Under ``contour`` the look-ahead foresees descent trapped in the
    horseshoe: the unit tracks the descent to there, and only there is the
    escape searched, off the loop.
    """
    w = _deferred(planner=PlannerParams(escape="contour"))
    out = w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    kinds = [job.kind for job in out.jobs]
    assert kinds == ["foresee"] and _one(out, "u").deliberating
    d = _one(w.apply([out.jobs[0].run(0.0)], 0.0), "u")  # the route lands
    assert d.route == "descent" and not d.deliberating
    step = w.view("u").stepper.params.step
    pos = (0.0, 0.0)
    for k in range(1, 3000):
        out = w.apply([_state("u", *pos, k)], float(k))
        d = _one(out, "u")
        if out.jobs:
            kinds.append(out.jobs[0].kind)
            if out.jobs[0].kind == "escape":
                break
            assert d.deliberating
            d = _one(w.apply([out.jobs[0].run(float(k))], float(k)), "u")  # the route lands
        assert d.status is DirectionStatus.EN_ROUTE
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
    else:
        pytest.fail("no escape job")
    assert kinds == ["foresee", "escape"]
    assert d.deliberating and out.jobs[0].kind == "escape"
    d = _one(w.apply([out.jobs[0].run(float(k)), _state("u", *pos)], float(k)), "u")
    assert d.status is DirectionStatus.ESCAPING
    assert math.isfinite(d.vector[0])


def test_with_an_origin_directions_carry_true_bearing_and_lat_lon_lookahead():
    from pfp_service.geo import Origin

    w = _world(origin=Origin(lat=59.9, lon=10.7))
    d = _one(w.apply([_state("u", 0, 0), GoalSet("u", Goal(position=(0, 1000)))], 0.0), "u")
    assert d.heading_deg == 0.0 and 0.0 <= d.true_bearing_deg < 1e-6
    assert len(d.lookahead_geo) == len(d.lookahead) == 5
    assert d.lookahead_geo[0].lat > 59.9 and abs(d.lookahead_geo[0].lon - 10.7) < 1e-6
    decode_direction(encode(d))


def test_a_threat_change_redirects_only_the_units_it_can_reach():
    w = _world()
    w.apply([_state("near", 0, 0), GoalSet("near", Goal(position=(10, 10)))], 0.0)
    w.apply([_state("far", 5000, 5000), GoalSet("far", Goal(position=(5100, 5000)))], 0.0)
    out = w.apply([ThreatPut("e1", ThreatUpdate(position=(4, 6), **T))], 1.0)
    assert [d.unit for d in out.directions] == ["near"]
    assert _events(out, ReplanEvent)[0].units == ["near"]
    # the far unit's next direction is what the full field says, all the same
    d = _one(w.apply([_state("far", 5000, 5000)], 2.0), "far")
    assert d.vector == (1.0, 0.0) or math.isclose(d.vector[0], 1.0)
    out = w.apply([ThreatRemoved("e1")], 3.0)
    assert [d.unit for d in out.directions] == ["near"]
    out = w.apply([ThreatPut("e2", ThreatUpdate(position=(5050, 5001), **T))], 4.0)
    assert [d.unit for d in out.directions] == ["far"]


def test_a_push_is_sent_again_until_the_unit_reports():
    w = _world(push_retry_s=0.25, push_retries=3)
    w.apply([_state("u", 0, 0), GoalSet("u", Goal(position=(10, 10)))], 0.0)
    out = w.apply([ThreatPut("e1", ThreatUpdate(position=(4, 6), **T))], 1.0)
    (push,) = out.directions
    assert w.counts()["pushes"] == 1
    assert _one(w.apply([Tick(1.25)], 1.25), "u") == push  # the same direction again
    assert _one(w.apply([Tick(1.5)], 1.5), "u") == push
    d = _one(w.apply([_state("u", 0, 0, 9)], 1.6), "u")  # answered: no more re-sends
    assert d.seq == 9
    assert not w.apply([Tick(2.0)], 2.0).directions and w.counts()["pushes_resent"] == 2
    w.apply([ThreatPut("e2", ThreatUpdate(position=(6, 4), **T))], 3.0)
    for t in (3.25, 3.5, 3.75, 4.0, 4.25):
        w.apply([Tick(t)], t)
    assert w.counts()["pushes_resent"] == 5  # at most push_retries each


def test_a_peer_planner_gone_is_acted_on_only_after_the_debounce():
    """A router restart or a brief loss flaps the token: units move only if it stays gone."""
    w = _world(cluster=True, planner_id="p0", liveliness_debounce_s=1.0, unit_stale_s=60.0)
    w.apply([PeerPlanner("p1", True)], 0.0)
    units = [f"u{i}" for i in range(40)]
    w.apply([_state(u, 0.1 * i, 0) for i, u in enumerate(units)], 0.0)
    w.apply([GoalSet(u, Goal(position=(10, 10))) for u in units], 0.0)
    theirs = [u for u in units if not w.owns(u)]
    assert theirs and w.counts()["units_owned"] == len(units) - len(theirs)

    def answered(t: float) -> set[str]:
        out = w.apply([_state(u, 0.1 * i, 0) for i, u in enumerate(units)] + [Tick(t)], t)
        return {d.unit for d in out.directions}

    w.apply([PeerPlanner("p1", False)], 1.0)
    assert not answered(1.5) & set(theirs)  # gone, but within the debounce: still p1's
    w.apply([PeerPlanner("p1", True)], 1.8)  # back: the debounce is cancelled
    out = w.apply([Tick(3.0)], 3.0)  # the first loss's timer is due: nothing moves
    assert not out.directions and w.counts()["units_owned"] == len(units) - len(theirs)
    assert not answered(3.1) & set(theirs)

    w.apply([PeerPlanner("p1", False)], 4.0)
    w.apply([PeerPlanner("p1", False)], 4.5)  # a repeated DELETE does not restart the debounce
    assert not w.apply([Tick(4.99)], 4.99).directions
    out = w.apply([Tick(5.0)], 5.0)  # gone for the whole debounce: its units are taken over, told at once
    assert {d.unit for d in out.directions} == set(theirs)
    assert all(d.status is DirectionStatus.EN_ROUTE and d.planner == "p0" for d in out.directions)
    assert w.counts()["units_owned"] == len(units) and answered(5.1) == set(units)

    w.apply([PeerPlanner("p1", True)], 6.0)  # a real comeback takes its share back at once
    assert w.counts()["units_owned"] == len(units) - len(theirs)
