"""The live world model without Zenoh: time is a number, messages are structs."""

from __future__ import annotations

import numpy as np

from pfp_service.core import PlannerParams
from pfp_service.service.preview import preview
from pfp_service.service.world import World, WorldSettings
from pfp_service.wire import DirectionStatus, Goal, PreviewRequest, ThreatUpdate, UnitState, WhatIfThreat

T = dict(facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7, skew=2.0)


def _world(**kw) -> World:
    return World(WorldSettings(planner=PlannerParams(intensity="density", delta=0.08), **kw))


def _state(x, y, seq=None):
    return UnitState(position=(x, y), seq=seq)


def test_no_goal_then_goal():
    w = _world()
    assert w.apply_state("u1", _state(0, 0, 1), 0.0) == {"u1"}
    (d,) = w.directions({"u1"})
    assert d.status is DirectionStatus.NO_GOAL and d.seq == 1
    assert w.apply_goal("u1", Goal(position=(10, 10)), 0.0) == {"u1"}
    (d,) = w.directions({"u1"})
    assert d.status is DirectionStatus.EN_ROUTE
    assert abs(d.heading_deg - 45.0) < 1e-9 and len(d.lookahead) == 5
    assert w.cancel_goal("u1") == {"u1"}
    assert w.directions({"u1"})[0].status is DirectionStatus.NO_GOAL


def test_threat_changes_mark_every_guided_unit():
    w = _world()
    for uid, pos in (("a", (0, 0)), ("b", (1, 0)), ("c", (2, 0))):
        w.apply_state(uid, _state(*pos), 0.0)
    w.apply_goal("a", Goal(position=(10, 10)), 0.0)
    w.apply_goal("b", Goal(position=(10, 10)), 0.0)
    assert w.apply_threat("e1", ThreatUpdate(position=(4, 6), **T), 1.0) == {"a", "b"}
    assert len(w.field) == 1
    assert w.remove_threat("e1") == {"a", "b"}
    assert w.remove_threat("e1") == set()


def test_threat_ttl_expires():
    w = _world(threat_ttl_s=30.0)
    w.apply_state("a", _state(0, 0), 0.0)
    w.apply_goal("a", Goal(position=(10, 10)), 0.0)
    w.apply_threat("short", ThreatUpdate(position=(4, 6), ttl_s=5.0, **T), 0.0)
    w.apply_threat("default", ThreatUpdate(position=(7, 3), **T), 0.0)
    dirty, expired, _ = w.expire(4.9)
    assert expired == [] and not dirty
    dirty, expired, _ = w.expire(5.0)
    assert expired == ["short"] and dirty == {"a"}
    _, expired, _ = w.expire(30.0)
    assert expired == ["default"] and len(w.field) == 0


def test_liveliness_debounce_and_silence():
    w = _world(liveliness_debounce_s=2.0, unit_stale_s=10.0)
    w.apply_state("a", _state(0, 0), 0.0)
    w.apply_goal("a", Goal(position=(10, 10)), 0.0)
    w.liveliness("a", False, 1.0)
    w.liveliness("a", True, 2.5)  # a router restart: back within the debounce
    assert w.expire(4.0)[2] == []
    w.liveliness("a", False, 5.0)
    assert w.expire(6.9)[2] == []
    assert w.expire(7.0)[2] == ["a"]
    assert w.directions({"a"}) == []  # stale: nothing
    w.apply_state("a", _state(0.1, 0.1), 8.0)
    assert w.directions({"a"})[0].status is DirectionStatus.EN_ROUTE
    assert w.expire(18.0)[2] == []
    assert w.expire(18.2)[2] == ["a"]  # silent past unit_stale_s


def test_live_stream_matches_preview():
    w = _world()
    w.apply_threat("e1", ThreatUpdate(position=(4, 6), **T), 0.0)
    w.apply_threat("e2", ThreatUpdate(position=(7, 3), **T), 0.0)
    w.apply_state("u", _state(0, 0), 0.0)
    w.apply_goal("u", Goal(position=(10, 10)), 0.0)
    pv = preview(w.view("u"), "u", None, lambda: 0.0, 1.0, 10_000)
    step = pv.params.step
    pos = (0.0, 0.0)
    track = [pos]
    for k in range(1, 400):
        (d,) = w.directions({"u"})
        if d.status is not DirectionStatus.EN_ROUTE:
            break
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
        track.append(pos)
        w.apply_state("u", _state(*pos, k), float(k))
    assert d.status is DirectionStatus.ARRIVED
    np.testing.assert_array_equal(np.array(track), np.array(pv.path))


def test_what_if_preview_leaves_the_world_alone():
    w = _world()
    w.apply_threat("e1", ThreatUpdate(position=(4, 6), **T), 0.0)
    w.apply_state("u", _state(0, 0), 0.0)
    w.apply_goal("u", Goal(position=(10, 10)), 0.0)
    before = w.directions({"u"})[0]
    req = PreviewRequest(threats=[WhatIfThreat(id="x", position=(5, 5), **T)], goal=(0, 10))
    pv = preview(w.view("u"), "u", req, lambda: 0.0, 1.0, 10_000)
    assert pv.path[-1] != (10.0, 10.0)
    assert len(w.field) == 1 and w.units["u"].goal.position == (10, 10)
    assert w.directions({"u"})[0].vector == before.vector


def test_preview_budget_bounds_time():
    clock_calls = iter(range(10**9))
    w = _world()
    w.apply_state("u", _state(0, 0), 0.0)
    w.apply_goal("u", Goal(position=(1e6, 0)), 0.0)
    # a clock that advances 1 s per reading: the budget of 0.5 s is spent at the first check
    pv = preview(
        w.view("u"),
        "u",
        PreviewRequest(step=1.0, max_iter=10_000_000),
        lambda: float(next(clock_calls)),
        0.5,
        10**7,
    )
    assert pv.status.value == "max_iter" and "time budget" in pv.reason
    assert pv.steps == 64


def test_preview_uses_the_live_units_parameters_after_threats_change():
    """Parameters are fixed when the goal is set; a later preview must not re-derive them."""
    w = World(WorldSettings())  # peak intensity, scale-free defaults
    w.apply_state("u", _state(0, 0), 0.0)
    w.apply_goal("u", Goal(position=(10, 10)), 0.0)  # no threats yet: delta resolves to 1
    w.apply_threat("e1", ThreatUpdate(position=(4, 6), **T), 1.0)
    w.apply_threat("e2", ThreatUpdate(position=(7, 3), **T), 1.0)
    pv = preview(w.view("u"), "u", None, lambda: 0.0, 1.0, 10_000)
    assert pv.params.delta == w.units["u"].stepper.params.delta
    step, pos, track = pv.params.step, (0.0, 0.0), [(0.0, 0.0)]
    for k in range(1, 600):
        (d,) = w.directions({"u"})
        if d.status is not DirectionStatus.EN_ROUTE:
            break
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
        track.append(pos)
        w.apply_state("u", _state(*pos, k), 2.0 + k)
    assert d.status is DirectionStatus.ARRIVED
    np.testing.assert_allclose(np.array(track), np.array(pv.path), atol=1e-9)


def test_mission_bounds_reach_the_stepper_and_levels_stay_on_the_wire():
    bounds = ((-5.0, -5.0), (15.0, 15.0))
    w = World(WorldSettings(planner=PlannerParams(intensity="density"), bounds=bounds))
    w.apply_state("u", _state(1.0, 1.0), 0.0)
    w.apply_goal("u", Goal(position=(10, 10)), 0.0)
    assert w.units["u"].stepper.bounds == bounds
    # an absurd weight at density intensity: the level is clamped to what the wire carries
    w.apply_threat(
        "hot", ThreatUpdate(position=(1.0, 1.0), sigma_range=0.01, sigma_lateral=0.01, weight=1e6), 0.0
    )
    (d,) = w.directions({"u"})
    from pfp_service.wire import decode_direction, encode

    assert decode_direction(encode(d)).threat_level == d.threat_level <= 1e9
