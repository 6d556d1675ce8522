"""The live world as a state machine: plain numbers in, directions and events out, no Zenoh."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import PlannerParams
from pfp_service.errors import InputError
from pfp_service.wire import (
    GOAL_CANCELLED,
    ArrivedEvent,
    DirectionStatus,
    ForgottenEvent,
    Goal,
    PreviewRequest,
    RejectedEvent,
    ReplanEvent,
    StaleEvent,
    ThreatUpdate,
    TrappedEvent,
    UnitState,
    WhatIfThreat,
    decode_direction,
    decode_event,
    decode_world_snapshot,
    encode,
    keys,
)
from pfp_service.world.preview import preview
from pfp_service.world.translate import decode_plan_result, fit_reply
from pfp_service.world.world import (
    GoalCancelled,
    GoalSet,
    InputRejected,
    StateReported,
    ThreatPut,
    ThreatRemoved,
    Tick,
    TokenChanged,
    World,
    WorldSettings,
)

pytestmark = pytest.mark.unit

T = dict(facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7, skew=2.0)


def _world(**kw) -> World:
    planner = kw.pop("planner", PlannerParams(intensity="density", delta=0.08))
    return World(WorldSettings(planner=planner, **kw))


def _state(uid, x, y, seq=None):
    return StateReported(uid, UnitState(position=(x, y), seq=seq))


def _events(out, cls):
    return [e for e in out.events if isinstance(e, cls)]


def _one(out, uid):
    (d,) = [d for d in out.directions if d.unit == uid]
    return d


def test_a_state_for_an_unknown_unit_gets_no_goal_then_a_goal_guides_it():
    w = _world()
    out = w.apply([_state("u1", 0, 0, 1)], 0.0)
    d = _one(out, "u1")
    assert d.status is DirectionStatus.NO_GOAL and d.seq == 1 and d.vector == (0.0, 0.0)
    assert d.reason == ""  # none was ever put: a client puts its goal (again) on this one
    d = _one(w.apply([GoalSet("u1", Goal(position=(10, 10)))], 0.0), "u1")
    assert d.status is DirectionStatus.EN_ROUTE
    assert abs(d.heading_deg - 45.0) < 1e-9 and len(d.lookahead) == 5
    d = _one(w.apply([GoalCancelled("u1")], 0.0), "u1")
    assert d.status is DirectionStatus.NO_GOAL and d.reason == GOAL_CANCELLED  # and leaves this one be
    assert not w.apply([GoalCancelled("u1")], 0.0)  # nothing to cancel: nothing goes out
    assert _one(w.apply([_state("u1", 0, 0, 2)], 0.1), "u1").reason == GOAL_CANCELLED  # said every report
    assert w.snapshot(0.1).units[0].reason == GOAL_CANCELLED  # and in the world reply
    assert _one(w.apply([GoalSet("u1", Goal(position=(10, 10)))], 0.2), "u1").reason == ""


def test_a_goal_before_any_report_waits_for_the_report():
    w = _world()
    assert not w.apply([GoalSet("u", Goal(position=(10, 10)))], 0.0).directions
    assert _one(w.apply([_state("u", 0, 0)], 0.0), "u").status is DirectionStatus.EN_ROUTE


def test_threat_changes_redirect_guided_units_with_one_structured_replan_event():
    w = _world()
    w.apply([_state(u, i, 0) for i, u in enumerate("abc")], 0.0)
    w.apply([GoalSet("a", Goal(position=(10, 10))), GoalSet("b", Goal(position=(10, 10)))], 0.0)
    out = w.apply([ThreatPut("e1", ThreatUpdate(position=(4, 6), **T))], 1.0)
    assert {d.unit for d in out.directions} == {"a", "b"}
    (ev,) = _events(out, ReplanEvent)
    assert ev.units == ["a", "b"] and ev.reason == "threat e1 put"
    assert [(c.threat, c.change, c.position) for c in ev.changes] == [("e1", "put", (4.0, 6.0))]
    decode_event(encode(ev))  # within the schema
    out = w.apply([ThreatRemoved("e1")], 2.0)
    assert _events(out, ReplanEvent)[0].changes[0].change == "removed"


def test_a_threat_deleted_that_was_never_known_changes_nothing():
    w = _world()
    w.apply([_state("a", 0, 0), GoalSet("a", Goal(position=(10, 10)))], 0.0)
    out = w.apply([ThreatRemoved("ghost")], 1.0)
    assert not out.directions and not out.events


def test_a_batch_of_many_threat_changes_gives_one_event_within_the_schema():
    w = _world()
    w.apply([_state("a", 0, 0), GoalSet("a", Goal(position=(10, 10)))], 0.0)
    puts = [ThreatPut(f"t{i}", ThreatUpdate(position=(50 + i, 50), **T)) for i in range(300)]
    (ev,) = _events(w.apply(puts, 1.0), ReplanEvent)
    assert len(ev.changes) == 64 and ev.more == 236 and len(ev.reason) < 200
    decode_event(encode(ev))


def test_threat_ttl_expires_on_tick():
    w = _world(threat_ttl_s=30.0)
    w.apply([_state("a", 0, 0), GoalSet("a", Goal(position=(10, 10)))], 0.0)
    w.apply([ThreatPut("short", ThreatUpdate(position=(4, 6), ttl_s=5.0, **T))], 0.0)
    w.apply([ThreatPut("default", ThreatUpdate(position=(7, 3), **T))], 0.0)
    assert not w.apply([Tick(4.9)], 4.9)
    out = w.apply([Tick(5.0)], 5.0)
    assert [c.threat for c in _events(out, ReplanEvent)[0].changes] == ["short"]
    assert [d.unit for d in out.directions] == ["a"]
    w.apply([Tick(30.0)], 30.0)
    assert len(w.field) == 0
    # a re-put threat lives on: the old timer must not expire it
    w.apply([ThreatPut("x", ThreatUpdate(position=(4, 6), ttl_s=5.0, **T))], 40.0)
    w.apply([ThreatPut("x", ThreatUpdate(position=(4, 6), ttl_s=50.0, **T))], 44.0)
    w.apply([Tick(46.0)], 46.0)
    assert len(w.field) == 1


def test_liveliness_debounce_silence_and_stale_events():
    w = _world(liveliness_debounce_s=2.0, unit_stale_s=10.0)
    w.apply([_state("a", 0, 0), GoalSet("a", Goal(position=(10, 10)))], 0.0)
    w.apply([TokenChanged("a", False)], 1.0)
    w.apply([TokenChanged("a", True)], 2.5)  # a router restart: back within the debounce
    assert not _events(w.apply([Tick(4.0)], 4.0), StaleEvent)
    w.apply([TokenChanged("a", False)], 5.0)
    assert not _events(w.apply([Tick(6.9)], 6.9), StaleEvent)
    (ev,) = _events(w.apply([Tick(7.0)], 7.0), StaleEvent)
    assert ev.unit == "a" and "token" in ev.reason and w.counts()["units_stale"] == 1
    out = w.apply([ThreatPut("e", ThreatUpdate(position=(4, 6), **T))], 7.5)
    assert not out.directions  # stale: nothing
    assert _one(w.apply([_state("a", 0.1, 0.1)], 8.0), "a").status is DirectionStatus.EN_ROUTE
    assert w.counts()["units_stale"] == 0
    assert not _events(w.apply([Tick(18.0)], 18.0), StaleEvent)
    (ev,) = _events(w.apply([Tick(18.2)], 18.2), StaleEvent)
    assert "silent" in ev.reason  # silent past unit_stale_s


def test_a_token_alone_makes_no_unit():
    w = _world()
    w.apply([TokenChanged("nobody", True), TokenChanged("nobody", False)], 0.0)
    assert w.counts()["units"] == 0


def test_stale_units_are_forgotten_with_an_event_and_their_memory():
    w = _world(unit_stale_s=1.0, unit_forget_s=5.0)
    w.apply([_state(f"u{i}", i, 0) for i in range(100)], 0.0)
    w.apply([GoalSet("u1", Goal(position=(10, 10)))], 0.0)
    assert len(_events(w.apply([Tick(1.5)], 1.5), StaleEvent)) == 100
    assert not _events(w.apply([Tick(6.0)], 6.0), ForgottenEvent)
    out = w.apply([Tick(6.5)], 6.5)
    assert len(_events(out, ForgottenEvent)) == 100
    assert w.counts() == {
        "units": 0,
        "units_stale": 0,
        "threats": 0,
        "zones": 0,
        "deliberating": 0,
        "overload": 0,
        "rejected": 0,
        "units_owned": 0,
        "pushes": 0,
        "pushes_resent": 0,
        "faults": 0,
    }
    assert not w._units and not w._timers  # nothing left behind


def test_limits_refuse_with_rejected_events_and_count_overload():
    w = _world(max_units=2, max_threats=1)
    out = w.apply([_state("a", 0, 0), _state("b", 0, 0), _state("c", 0, 0)], 0.0)
    assert {d.unit for d in out.directions} == {"a", "b"}
    (ev,) = _events(out, RejectedEvent)
    assert ev.key == keys.unit_state("default", "c") and "max_units" in ev.reason
    out = w.apply([ThreatPut("t1", ThreatUpdate(position=(4, 6), **T))], 0.0)
    out = w.apply([ThreatPut("t2", ThreatUpdate(position=(4, 6), **T))], 0.0)
    assert "max_threats" in _events(out, RejectedEvent)[0].reason
    w.apply([ThreatPut("t1", ThreatUpdate(position=(5, 6), **T))], 0.0)  # a known one may move
    assert w.counts()["overload"] == 2 and w.counts()["threats"] == 1


def test_rejections_are_rate_limited_per_kind_and_the_rest_counted():
    w = _world()
    key = keys.unit_state("default", "x")
    bad = [InputRejected(key, InputError("$", "malformed JSON")) for _ in range(1000)]
    out = w.apply(bad, 0.0)
    assert len(_events(out, RejectedEvent)) == 5
    (ev,) = _events(w.apply([InputRejected(key, InputError("$", "x"))], 1.5), RejectedEvent)
    assert ev.suppressed == 995 and w.counts()["rejected"] == 1001
    other = InputRejected(keys.threat("default", "t"), InputError("$", "y"))
    assert len(_events(w.apply([other], 1.6), RejectedEvent)) == 1  # another kind has its own budget


def _walk_live(w, uid, pos, step, steps, t0=0.0):
    """Move a unit exactly along its directions; return its track and the last direction."""
    track = [pos]
    d = None
    for k in range(1, steps + 1):
        d = _one(w.apply([_state(uid, *pos, k)], t0 + k), uid)
        if d.status not in (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING):
            break
        s = min(step, d.distance_to_goal) if d.distance_to_goal is not None else step  # never past the goal
        pos = (pos[0] + s * d.vector[0], pos[1] + s * d.vector[1])
        track.append(pos)
    return track, d


def test_arrived_fires_once():
    w = _world()
    w.apply([_state("u", 0, 0), GoalSet("u", Goal(position=(10, 10)))], 0.0)
    step = w.view("u").stepper.params.step
    track, d = _walk_live(w, "u", (0.0, 0.0), step, 2000)
    assert d.status is DirectionStatus.ARRIVED
    evs = []
    for k in range(3):  # it keeps reporting at the goal
        evs += _events(w.apply([_state("u", *track[-1])], 3000.0 + k), ArrivedEvent)
    assert evs == []


def _horseshoe():
    """tests/unit/test_escape.py's horseshoe as wire messages: open towards the start, its back to the goal."""
    out = []
    for k in range(9):
        b = math.radians(-55 + 200 * k / 8)
        pos = (60 + 12 * math.sin(b), 60 + 12 * math.cos(b))
        update = ThreatUpdate(position=pos, facing_deg=225, sigma_range=4, sigma_lateral=4, skew=0.5)
        out.append(ThreatPut(f"h{k}", update))
    return out


def test_trapped_fires_once_per_trap_and_a_walked_out_unit_is_judged_afresh():
    w = _world(planner=PlannerParams(escape="none"))
    w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    step = w.view("u").stepper.params.step
    events = []
    pos = (0.0, 0.0)
    for k in range(1, 3000):
        out = w.apply([_state("u", *pos, k)], float(k))
        events += _events(out, TrappedEvent)
        d = _one(out, "u")
        if d.status is DirectionStatus.TRAPPED:
            break
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
    assert len(events) == 1 and events[0].position == pos
    for k in range(5):  # standing in the trap: no more events
        assert not _events(w.apply([_state("u", *pos)], 4000.0 + k), TrappedEvent)
    out = w.apply([_state("u", 0.0, 0.0)], 5000.0)  # carried out by hand: guided again
    assert _one(out, "u").status is DirectionStatus.EN_ROUTE


def test_a_goal_cancelled_mid_escape_stops_the_escape():
    w = _world(planner=PlannerParams(escape="contour"))
    w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    step = w.view("u").stepper.params.step
    pos, into = (0.0, 0.0), 0
    for k in range(1, 3000):
        d = _one(w.apply([_state("u", *pos, k)], float(k)), "u")
        into += d.status is DirectionStatus.ESCAPING
        if into == 3:
            break
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
    assert d.status is DirectionStatus.ESCAPING, d
    out = w.apply([GoalCancelled("u"), _state("u", *pos)], 9000.0)
    assert _one(out, "u").status is DirectionStatus.NO_GOAL
    assert w.view("u").stepper is None


@pytest.mark.parametrize("escape", ["contour", "random", "waypoint", "global", "auto"])
def test_a_preview_k_steps_into_an_escape_matches_the_live_track(escape):
    w = _world(planner=PlannerParams(escape=escape))
    w.apply([*_horseshoe(), _state("u", 0, 0), GoalSet("u", Goal(position=(100, 100)))], 0.0)
    step = w.view("u").stepper.params.step
    pos, k, into = (0.0, 0.0), 0, 0
    while into < 5:  # walk live until 5 advisories into the first escape
        k += 1
        assert k < 5000, "never escaped"
        d = _one(w.apply([_state("u", *pos, k)], float(k)), "u")
        assert d.status in (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING), d
        into += d.status is DirectionStatus.ESCAPING
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
    # the unit was told d at its last report and will next report at pos
    pv = preview(w.view("u"), None, lambda: 0.0, 60.0, 100_000)
    live, last = _walk_live(w, "u", pos, step, 100_000, t0=1e5)
    # the same verdict (global on this horseshoe may hand over too early: that is path quality, not this)
    assert {"reached": DirectionStatus.ARRIVED, "trapped": DirectionStatus.TRAPPED}[
        pv.status.value
    ] is last.status
    assert pv.escape_steps > 0 or escape == "auto"
    assert len(pv.path) == len(live) + 1, (len(pv.path), len(live))
    err = np.max(np.hypot(*(np.array(pv.path[1:]) - np.array(live)).T))
    assert err <= 1e-6 * pv.length, (escape, err)


def test_each_unit_has_its_own_random_escape_and_its_preview_the_same():
    w = _world(planner=PlannerParams(escape="random"))
    w.apply([*_horseshoe()], 0.0)
    keys_seen = set()
    for uid in ("a", "b"):
        w.apply([_state(uid, 0, 0), GoalSet(uid, Goal(position=(100, 100)))], 0.0)
        keys_seen.add(w.view(uid).stepper.unit_key)
    assert len(keys_seen) == 2


def test_what_if_preview_leaves_the_world_alone():
    w = _world()
    w.apply([ThreatPut("e1", ThreatUpdate(position=(4, 6), **T))], 0.0)
    before = _one(w.apply([_state("u", 0, 0), GoalSet("u", Goal(position=(10, 10)))], 0.0), "u")
    req = PreviewRequest(threats=[WhatIfThreat(id="x", position=(5, 5), **T)], goal=(0, 10))
    pv = preview(w.view("u"), req, lambda: 0.0, 1.0, 10_000)
    assert pv.path[-1] != (10.0, 10.0)
    req = PreviewRequest(threats=[WhatIfThreat(id="x", position=(5, 5), **T)])
    preview(w.view("u"), req, lambda: 0.0, 1.0, 10_000)  # on the live stepper's copy
    assert len(w.field) == 1 and w.snapshot(0.0).units[0].goal == (10.0, 10.0)
    assert _one(w.apply([_state("u", 0, 0)], 0.0), "u").vector == before.vector


def test_preview_budget_bounds_time():
    clock_calls = iter(range(10**9))
    w = _world()
    w.apply([_state("u", 0, 0), GoalSet("u", Goal(position=(1e6, 0)))], 0.0)
    # a clock that advances 1 s per reading: the budget of 0.5 s is spent at the first check
    pv = preview(
        w.view("u"),
        PreviewRequest(step=1.0, max_iter=10_000_000),
        lambda: float(next(clock_calls)),
        0.5,
        10**7,
    )
    assert pv.status.value == "max_iter" and "time budget" in pv.reason
    assert pv.steps == 64


def test_a_reply_over_the_payload_limit_is_decimated_to_fit():
    w = _world()
    w.apply([_state("u", 0, 0), GoalSet("u", Goal(position=(1e4, 0)))], 0.0)
    pv = preview(w.view("u"), PreviewRequest(step=0.25), lambda: 0.0, 60.0, 10**6)
    assert len(encode(pv)) > 256 * 1024
    data = fit_reply(pv)
    back = decode_plan_result(data)
    assert len(data) <= 256 * 1024 and back.path_decimated and back.steps == pv.steps
    assert back.path[0] == pv.path[0] and back.path[-1] == pv.path[-1]
    short = preview(w.view("u"), None, lambda: 0.0, 60.0, 10**6)
    assert not decode_plan_result(fit_reply(short)).path_decimated


def test_preview_uses_the_live_units_parameters_after_threats_change():
    """Parameters are fixed when the goal is set; a later preview must not re-derive them."""
    w = World(WorldSettings())  # peak intensity, scale-free defaults
    w.apply([_state("u", 0, 0), GoalSet("u", Goal(position=(10, 10)))], 0.0)  # no threats: delta is 1
    w.apply([ThreatPut(i, ThreatUpdate(position=p, **T)) for i, p in (("e1", (4, 6)), ("e2", (7, 3)))], 1.0)
    view = w.view("u")
    pv = preview(view, None, lambda: 0.0, 1.0, 10_000)
    assert pv.params.delta == view.stepper.params.delta
    track, d = _walk_live(w, "u", (0.0, 0.0), pv.params.step, 600, t0=2.0)
    assert d.status is DirectionStatus.ARRIVED
    np.testing.assert_allclose(np.array(track), np.array(pv.path), atol=1e-9)


def test_mission_bounds_reach_the_stepper_and_levels_stay_on_the_wire():
    bounds = ((-5.0, -5.0), (15.0, 15.0))
    w = World(WorldSettings(planner=PlannerParams(intensity="density"), bounds=bounds))
    w.apply([_state("u", 1.0, 1.0), GoalSet("u", Goal(position=(10, 10)))], 0.0)
    assert w.view("u").stepper.bounds == bounds
    # an absurd weight at density intensity: the level is clamped to what the wire carries
    hot = ThreatUpdate(position=(1.0, 1.0), sigma_range=0.01, sigma_lateral=0.01, weight=1e6)
    d = _one(w.apply([ThreatPut("hot", hot)], 0.0), "u")
    assert decode_direction(encode(d)).threat_level == d.threat_level <= 1e9


def test_snapshot_lists_units_and_threats_within_the_schema():
    w = _world()
    w.apply([_state("b", 1, 1), _state("a", 0, 0), GoalSet("a", Goal(position=(10, 10)))], 0.0)
    w.apply([ThreatPut("e1", ThreatUpdate(position=(4, 6), ttl_s=30.0, **T))], 0.0)
    snap = decode_world_snapshot(encode(w.snapshot(10.0)))
    assert [u.id for u in snap.units] == ["a", "b"]
    assert (
        snap.units[0].status is DirectionStatus.EN_ROUTE and snap.units[1].status is DirectionStatus.NO_GOAL
    )
    assert snap.units[0].last_seen_s == 10.0 and snap.threats[0].ttl_s == 20.0
