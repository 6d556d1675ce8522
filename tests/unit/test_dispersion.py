"""Dispersion (issue 33): the repulsive term's exact gradient, the neighbour index, right of way and deadlocks.

The crowds are driven through the sans-I/O world in process (``benchmarks._crowd.simulate``),
and every figure is measured on the tracks, not taken from the world.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks import _crowd
from pfp_service.core.dispersion import REACH, NeighbourIndex, brute_gradients, gradient, potential
from pfp_service.wire import DeadlockEvent, DirectionStatus
from pfp_service.world.separations import SEPARATION_M, DispersionSettings

pytestmark = pytest.mark.unit

coord = st.floats(-300.0, 300.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(
    p=st.tuples(coord, coord),
    q=st.lists(st.tuples(coord, coord), min_size=1, max_size=8),
    s=st.floats(5.0, 120.0),
)
def test_the_gradient_is_exact_against_finite_differences(p, q, s):
    p, q = np.array(p), np.array(q)
    rho = np.full(len(q), REACH * s)
    d = np.hypot(*(q - p).T)
    if np.any(d < 1e-2) or np.any(np.abs(d - rho) < 1e-2):  # the cone's tip and the reach's edge: no FD there
        return
    h = 1e-6
    fd = [
        (potential(p + e, q, rho) - potential(p - e, q, rho)) / (2 * h)
        for e in (np.array([h, 0]), np.array([0, h]))
    ]
    np.testing.assert_allclose(gradient(p, q, rho), fd, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_index_gives_what_every_pair_gives(seed):
    rng = np.random.default_rng(seed)
    n = 400
    pts = rng.uniform(-1500, 1500, (n, 2))
    pts[7] = pts[3]  # two units on one point: parted, one west and one east
    seps = rng.choice([5.0, 50.0], n)
    index = NeighbourIndex(pts, seps)
    got = index.gradients(np.arange(n))
    np.testing.assert_allclose(got, brute_gradients(pts, seps), rtol=1e-12, atol=1e-15)
    for i in rng.choice(n, 30, replace=False):  # and the one-point formula, pair by pair
        others = np.delete(np.arange(n), i)
        rho = REACH * np.maximum(seps[i], seps[others])
        if i not in (3, 7):
            np.testing.assert_allclose(got[i], gradient(pts[i], pts[others], rho), rtol=1e-12, atol=1e-15)
    assert got[3, 0] > 0 > got[7, 0]  # grad: the lower index is pushed west (descent goes -grad)
    sub = np.array([5, 3, 99])
    np.testing.assert_allclose(index.gradients(sub), got[sub])


def test_every_mobility_class_has_a_separation():
    from pfp_service.core.mobility import CLASSES

    assert set(SEPARATION_M) == set(CLASSES)
    s = DispersionSettings(enabled=True, classes={"d1": "foot"})
    assert s.separation("d1") == 5.0 and s.separation("v1") == 50.0


def test_two_units_in_one_gap_one_yields_and_both_arrive_apart():
    crowd = _crowd.one_gap()
    off = _crowd.simulate(crowd, None)
    record: list = []
    on = _crowd.simulate(crowd, DispersionSettings(enabled=True), record=record)
    assert off.closest_m < 25.0  # without dispersion they pass within metres: the case is a real one
    assert set(on.arrived_s) == {"u0000", "u0001"}
    assert on.closest_m >= 0.9 * 50.0
    held = [d for _, d in record if d.status is DirectionStatus.YIELDING]
    assert held and all(d.unit == "u0001" and "yielding to u0000" in d.reason for d in held)  # manned first
    assert all(d.vector == (0.0, 0.0) or "making room" in d.reason for d in held)


def test_manned_first_off_gives_the_way_by_id():
    crowd = _crowd.one_gap()
    crowd = _crowd.Crowd(crowd.name, crowd.starts, crowd.goals, ["unmanned", "manned"], crowd.threats)
    record: list = []
    _crowd.simulate(crowd, DispersionSettings(enabled=True, manned_first=False), record=record, limit_s=300.0)
    held = {d.unit for _, d in record if d.status is DirectionStatus.YIELDING}
    assert held == {"u0001"}  # u0001 is manned here, but the smaller id goes first


def test_a_deadlock_is_reported_and_cleared_in_bounded_time():
    crowd = _crowd.head_on()  # exactly on one line: the push alone holds them at a standstill
    record: list = []
    settings_ = DispersionSettings(enabled=True, deadlock_s=10.0, backoff_s=10.0)
    out = _crowd.simulate(crowd, settings_, record=record)
    assert out.deadlocks >= 1
    assert 0.0 < out.longest_deadlock_s <= 30.0 and out.still_holding == 0
    assert set(out.arrived_s) == {"u0000", "u0001"}
    assert out.closest_m >= 0.9 * 50.0
    backing = [d for _, d in record if d.status is DirectionStatus.YIELDING and "backing off" in d.reason]
    assert backing and all(d.unit == "u0001" and d.vector != (0.0, 0.0) for d in backing)


def test_the_deadlock_event_names_both_units():
    from pfp_service.wire import Goal, UnitKind, UnitState
    from pfp_service.world import events as ev
    from pfp_service.world.world import World, WorldSettings

    w = World(
        WorldSettings(deliberation="deferred", dispersion=DispersionSettings(enabled=True, deadlock_s=3.0))
    )
    w.apply(
        [ev.GoalSet("m1", Goal(position=(0.0, 600.0))), ev.GoalSet("r1", Goal(position=(0.0, -600.0)))], 0.0
    )
    found = []
    for t in range(8):  # neither moves: r1 yields to m1, which does not draw away
        states = [
            ev.StateReported("m1", UnitState(position=(0.0, 0.0), kind=UnitKind.MANNED)),
            ev.StateReported("r1", UnitState(position=(0.0, 70.0), kind=UnitKind.UNMANNED)),
        ]
        found += [e for e in w.apply(states, float(t)).events if isinstance(e, DeadlockEvent)]
    assert found and (found[0].unit, found[0].other) == ("r1", "m1") and found[0].held_s >= 3.0
    assert "backs off" in found[0].reason


def test_off_is_todays_world_bit_for_bit_and_a_unit_alone_is_guided_as_without():
    crowd = _crowd.one_gap()
    base: list = []
    _crowd.simulate(crowd, None, record=base, limit_s=200.0)
    off: list = []
    _crowd.simulate(
        crowd,
        DispersionSettings(enabled=False, separation_m=dict.fromkeys(SEPARATION_M, 1e5)),
        record=off,
        limit_s=200.0,
    )
    alone: list = []  # on, but nobody within reach of anybody: no push, no hold
    _crowd.simulate(
        crowd,
        DispersionSettings(enabled=True, separation_m=dict.fromkeys(SEPARATION_M, 1e-3)),
        record=alone,
        limit_s=200.0,
    )
    assert base == off == alone and len(base) > 100


def test_advise_many_without_push_and_with_a_zero_push_agree():
    from pfp_service.core import PlannerParams, Threat, ThreatField, resolve
    from pfp_service.core.batch import advise_many
    from pfp_service.core.stepper import Stepper

    threats = [Threat.from_facing((5.0, 5.0), 225.0, 1.0, 0.7, 2.0, 1.0, "e1")]
    fld = ThreatField(threats, "density")
    pts = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])

    def steppers():
        return [
            Stepper(
                tuple(p), (10.0, 10.0), resolve(PlannerParams(escape="none"), tuple(p), (10.0, 10.0), threats)
            )
            for p in pts.tolist()
        ]

    assert advise_many(steppers(), fld, pts) == advise_many(steppers(), fld, pts, push=np.zeros((3, 2)))


def test_serve_config_turns_dispersion_on_with_classes_and_units(tmp_path):
    from pfp_service.node.config import load_config

    assert load_config(None, {}, {}).world_settings().dispersion == DispersionSettings()  # off by default
    toml = tmp_path / "pfp.toml"
    toml.write_text(
        'separation_m = {foot = 8}\nunit_class = {d1 = "foot"}\nmanned_first = false\ndeadlock_s = 4\n'
    )
    d = load_config(toml, {}, {"dispersion": True}).world_settings().dispersion
    assert d.enabled and not d.manned_first and d.deadlock_s == d.backoff_s == 4.0
    assert (d.separation("d1"), d.separation("v1"), d.separation_m["tracked"]) == (8.0, 50.0, 50.0)


def test_a_unit_on_a_route_squared_across_a_push_along_it_keeps_to_the_goals_side():
    """Gaps crowd, seed 5 (35 s to clear on main): ``u0192``'s route ran west, straight at its neighbours,
    and the push along it turned it back; squared across the push on the heading's side, the side
    flipped with the cross product's sign at each report, 5 m south, 5 m north, for 15 s.  The reports
    below are its own (heading, push); its goal lies north."""
    from types import SimpleNamespace

    from pfp_service.core import batch
    from pfp_service.core.advice import Advice, StepStatus
    from pfp_service.core.tracking import Route

    stepper = SimpleNamespace(goal=(385.0, 1760.0), params=SimpleNamespace(step=5.0))
    x, y = 147.3, -818.3
    sides = []
    for (hx, hy), push in (((-1.0, 0.06), (-1.67, 0.17)), ((-0.99, 0.15), (-1.62, -0.04))):
        adv = Advice(StepStatus.EN_ROUTE, hx, hy, 0.0, 2330.0, reach=55.0, route=Route.LOWER_EXPOSURE)
        out = [adv]
        batch._turn(out, [stepper], [[x, y]], np.array([push]), [])
        assert out[0].reach == 5.0 and out[0].dx * push[0] + out[0].dy * push[1] == pytest.approx(
            0.0, abs=1e-9
        )
        sides.append(out[0].dy > 0.0)
    assert sides == [True, True], "north both times: the goal's side, not the heading's flip"
    # a push clearly off the heading's line keeps the heading's side, whatever the goal's
    adv = Advice(StepStatus.EN_ROUTE, 1.0, 0.0, 0.0, 2330.0, reach=55.0, route=Route.LOWER_EXPOSURE)
    out = [adv]
    batch._turn(out, [stepper], [[x, y]], np.array([(1.5, 1.0)]), [])
    assert out[0].dx > 0.0 and out[0].dy < 0.0  # south-east: round the neighbours, on the heading's side
