"""``steering.direction``: the wire's bounds on a direction's figures (it is spelt without min/max, per unit of a wave)."""

from __future__ import annotations

import math

import pytest

from pfp_service.core.stepper import Advice, StepStatus
from pfp_service.errors import FINITE_LIMIT
from pfp_service.wire import DirectionStatus
from pfp_service.world import steering
from pfp_service.world.units import UnitRecord

pytestmark = pytest.mark.unit


def _rec() -> UnitRecord:
    rec = UnitRecord("u1", 1)
    rec.position, rec.seq = (3.0, 4.0), 7
    return rec


@pytest.mark.parametrize(
    ("level", "reach", "distance", "want_level", "want_reach", "want_distance"),
    [
        (2.5, 40.0, 100.0, 2.5, 40.0, 100.0),
        (-1.0, -3.0, 0.0, 0.0, 0.0, 0.0),
        (1e300, 1e300, 1e300, FINITE_LIMIT, FINITE_LIMIT, FINITE_LIMIT),
        (0.0, math.inf, 5.0, 0.0, None, 5.0),
        (0.0, math.nan, 5.0, 0.0, None, 5.0),
    ],
)
def test_direction_keeps_the_wire_bounds(level, reach, distance, want_level, want_reach, want_distance):
    rec = _rec()
    adv = Advice(StepStatus.EN_ROUTE, 0.0, -1.0, level, distance, "", False, reach, 0.0, 0.0)
    d, event, verdict = steering.direction(rec, adv, [], "p", deliberating=True)
    assert event is None and d.status is DirectionStatus.EN_ROUTE and d.deliberating
    assert (d.threat_level, d.reach_m, d.distance_to_goal) == (want_level, want_reach, want_distance)
    assert d.heading_deg == 180.0 and d.vector == (0.0, -1.0) and d.seq == 7
    assert verdict.distance == want_distance and verdict.vector == (0.0, -1.0)
    assert rec.last_status is None  # pure: the record is the owner's to write (``units.Units.steered``)


def test_a_trapped_verdict_fires_its_event_once_with_the_reason_cut():
    rec = _rec()
    adv = Advice(StepStatus.TRAPPED, 0.0, 0.0, 1.0, 9.0, "x" * 2000)
    d, event, verdict = steering.direction(rec, adv, [], "p", deliberating=False)
    assert d.status is DirectionStatus.TRAPPED and d.reach_m is None and d.heading_deg is None
    assert event is not None and event.reason == "x" * 1024 == d.reason
    assert verdict.reason == "x" * 2000 and verdict.vector is None
    rec.last_status = verdict.status  # as its owner keeps it
    assert steering.direction(rec, adv, [], "p", deliberating=False)[1] is None
