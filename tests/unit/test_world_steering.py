"""The reactive step (world/steering.py) and its look-ahead (world/lookahead.py): one batch, bulkheads per unit."""

from __future__ import annotations

import math

import pytest

from pfp_service.core import PlannerParams, Stepper, StepStatus, ThreatField, resolve
from pfp_service.core.stepper import Advice
from pfp_service.core.tracking import Route
from pfp_service.errors import FINITE_LIMIT
from pfp_service.geo import Origin
from pfp_service.wire import (
    ArrivedEvent,
    Direction,
    DirectionStatus,
    Goal,
    ThreatChange,
    ThreatUpdate,
    TrappedEvent,
    UnitPhase,
)
from pfp_service.world import reach, steering, translate
from pfp_service.world.lookahead import lookahead, within_map
from pfp_service.world.units import Started, UnitRecord
from pfp_service.world.world_records import Records

pytestmark = pytest.mark.unit

P = PlannerParams(intensity="density", delta=0.08)
FIELD = ThreatField(
    [translate.threat(ThreatUpdate(position=(50.0, 5.0), sigma_range=10.0, sigma_lateral=7.0), "t")],
    "density",
)


def _unit(recs: Records, uid: str, at: tuple[float, float], goal: tuple[float, float]) -> UnitRecord:
    rec = recs.book.add(uid, True, 0.0, reported=True)
    recs.book.reported(rec, at, 1, None, 0.0, 0.0)
    recs.book.set_goal(rec, Goal(position=goal), None)
    stepper = Stepper(at, goal, resolve(P, at, goal, FIELD.threats))
    recs.book.started(rec, Started((Goal(position=goal), at, stepper.params), stepper))
    return rec


def test_a_batch_is_advised_and_looked_ahead_from_where_each_step_ends():
    recs = Records()
    units = [_unit(recs, f"u{i}", (0.0, 10.0 * i), (100.0, 10.0 * i)) for i in range(4)]
    steered, failed = steering.steer(units, FIELD, None, 5)
    assert failed == [] and [r.id for r, _, _ in steered] == ["u0", "u1", "u2", "u3"]
    for rec, adv, track in steered:
        assert adv.status is StepStatus.EN_ROUTE and len(track) == 5
        assert track[0] == pytest.approx(adv.to)  # the first point is the end of the step advised
        assert all(math.dist(a, b) <= rec.stepper.params.step * 1.0001 for a, b in zip(track, track[1:]))  # type: ignore[union-attr]


def test_a_unit_whose_numbers_break_the_batch_fails_alone():
    recs = Records()
    good = [_unit(recs, f"g{i}", (0.0, 10.0 * i), (100.0, 10.0 * i)) for i in range(3)]
    bad = _unit(recs, "bad", (0.0, 50.0), (100.0, 50.0))
    bad.position = (math.nan, 0.0)  # a position the kernel cannot judge
    steered, failed = steering.steer([good[0], bad, *good[1:]], FIELD, None, 3)
    assert [r.id for r, _, _ in steered] == ["g0", "g1", "g2"]
    assert [r.id for r, _ in failed] == ["bad"]


def test_no_look_ahead_for_a_terminal_verdict_or_when_none_is_asked():
    recs = Records()
    there = _unit(recs, "there", (100.0, 0.0), (100.0, 0.0))
    on_way = _unit(recs, "on", (0.0, 0.0), (100.0, 0.0))
    (_, adv, track), (_, _, track2) = steering.steer([there, on_way], FIELD, None, 4)[0]
    assert adv.status is StepStatus.ARRIVED and track == [] and len(track2) == 4
    assert all(t == [] for _, _, t in steering.steer([on_way], FIELD, None, 0)[0])
    assert lookahead([], [], FIELD, 5, None) == []


def test_a_track_is_cut_at_its_first_point_off_the_map():
    big = FINITE_LIMIT * 2
    assert within_map([(0.0, 0.0), (1.0, 1.0)]) == [(0.0, 0.0), (1.0, 1.0)]
    assert within_map([(0.0, 0.0), (big, 0.0), (1.0, 1.0)]) == [(0.0, 0.0)]
    assert within_map([(math.nan, 0.0)]) == []


def test_a_direction_fires_its_event_once_on_a_change_of_status():
    recs = Records()
    rec = _unit(recs, "u", (0.0, 0.0), (100.0, 0.0))
    en_route = Advice(*_fields(StepStatus.EN_ROUTE))
    d, event, verdict = steering.direction(rec, en_route, [(0.0, 1.0)], "p", deliberating=False)
    assert event is None and d.status is DirectionStatus.EN_ROUTE and d.heading_deg == pytest.approx(0.0)
    assert rec.last_status is None  # pure: the verdict is the owner's to keep
    recs.book.steered(rec, verdict)
    assert rec.last_status is DirectionStatus.EN_ROUTE and rec.last_vector == (0.0, 1.0)
    arrived = Advice(*_fields(StepStatus.ARRIVED))
    d, event, verdict = steering.direction(rec, arrived, [], "p", deliberating=False)
    assert isinstance(event, ArrivedEvent) and d.status is DirectionStatus.ARRIVED and d.heading_deg is None
    recs.book.steered(rec, verdict)
    assert rec.phase is UnitPhase.ARRIVED and rec.last_vector is None and rec.last_distance == 10.0
    assert steering.direction(rec, arrived, [], "p", deliberating=False)[1] is None  # said once
    _, event, verdict = steering.direction(
        rec, Advice(*_fields(StepStatus.TRAPPED)), [], "p", deliberating=True
    )
    assert isinstance(event, TrappedEvent) and verdict.status is DirectionStatus.TRAPPED


def _fields(status: StepStatus) -> tuple:
    """An advice's fields in their order, for a unit heading north 10 m from its goal."""
    values = {
        "status": status,
        "dx": 0.0,
        "dy": 1.0,
        "level": 0.5,
        "distance": 10.0,
        "reason": "why",
        "deliberating": False,
        "reach": 1.0,
        "to_x": 0.0,
        "to_y": 1.0,
        "route": Route.NONE,
    }
    return tuple(values[f] for f in Advice._fields)


def test_no_goal_stands_still():
    recs = Records()
    rec = _unit(recs, "u", (0.0, 0.0), (100.0, 0.0))
    d = steering.no_goal(rec, "p")
    assert d.status is DirectionStatus.NO_GOAL and d.vector == (0.0, 0.0) and rec.last_status is None
    assert steering.NO_GOAL.status is DirectionStatus.NO_GOAL  # the verdict the world keeps with it


def test_lat_lon_are_added_where_they_mean_something_and_left_off_far_away():
    near = Direction(unit="a", status=DirectionStatus.EN_ROUTE, vector=(1.0, 0.0), lookahead=[(10.0, 10.0)])
    far = Direction(unit="b", status=DirectionStatus.EN_ROUTE, vector=(1.0, 0.0), lookahead=[(1e9, 1e9)])
    got = steering.geodetic([near, far], Origin(lat=52.0, lon=13.0), [(0.0, 0.0), (1e9, 1e9)])
    assert got[0].lookahead_geo and got[0].true_bearing_deg is not None
    assert got[1] == far  # thousands of km off the origin: metres only


def test_a_change_is_seen_by_the_units_whose_corridor_it_meets():
    recs = Records()
    crossing = _unit(recs, "x", (0.0, 0.0), (100.0, 0.0))
    far = _unit(recs, "far", (0.0, 5000.0), (100.0, 5000.0))
    touched = [translate.threat(ThreatUpdate(position=(50.0, 0.0), sigma_range=5.0, sigma_lateral=5.0), "n")]
    assert reach.reached([crossing, far], touched, "density") == [True, False]
    assert reach.reached([], touched, "density") == []


def test_a_replan_names_the_first_changes_and_counts_the_rest():
    changes = [ThreatChange(threat=f"t{i}", change="put") for i in range(6)]
    dirs = [
        Direction(unit=u, status=s, vector=(0.0, 0.0))
        for u, s in [
            ("b", DirectionStatus.EN_ROUTE),
            ("a", DirectionStatus.ESCAPING),
            ("c", DirectionStatus.NO_GOAL),
        ]
    ]
    ev = steering.replan("p", changes, dirs)
    assert ev.units == ["a", "b"] and ev.reason.endswith("; and 2 more") and ev.more == 0
