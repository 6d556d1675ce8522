"""A unit's own slope limit over Zenoh, over real terrain: its barriers built in a worker process (issue 32).

A planner (``PlannerNode``, in this process, ``--terrain-unit foot``) serves
over the Jacksboro DEM on a loopback router (``tests/net/test_live_mobility.py``'s).
A wheeled unit told it climbs 25 degrees is sent to a cell steeper than
wheels' 17 and gentler than 25: first ``trapped`` at 17 (the safe side), then,
once the node's slope worker has built the set for 25 off the loop and it has
landed, pushed ``en_route``.  A ``proc`` test: the set is built in a worker
process (``node.terrain.Sights``), as ``pfp serve`` builds it.
"""

from __future__ import annotations

import queue

import pytest

from pfp_service.wire import Goal, GoalMobility, ReplanEvent, UnitState, decode_event, encode, keys
from tests.net.test_live_mobility import MISSION, _planner, _until

pytestmark = pytest.mark.proc


def test_a_wheeled_unit_told_it_climbs_25_degrees_is_guided_up_a_slope_once_its_barriers_land(
    tmp_path, monkeypatch
):
    with _planner(tmp_path, monkeypatch, upper_deg=25.0) as (c, directions, _rejected, (goal, start)):
        replans: queue.Queue = queue.Queue()
        sub = c.declare_subscriber(
            keys.event(MISSION, "replan"), lambda s: replans.put(decode_event(s.payload.to_bytes()))
        )
        try:
            mob = GoalMobility(kind="wheeled", max_slope_deg=25.0)
            c.put(keys.unit_state(MISSION, "truck"), encode(UnitState(position=start, seq=1, mobility=mob)))
            c.put(keys.unit_goal(MISSION, "truck"), encode(Goal(position=goal, tolerance=1.0)))
            first = _until(directions, lambda d: d.unit == "truck" and d.status.value != "no_goal", 120.0)
            assert first.status.value == "trapped" and "slope>17deg" in (first.reason or ""), first
            d = _until(directions, lambda d: d.unit == "truck" and d.status.value == "en_route", 150.0)
            assert "slope>17deg" not in (d.reason or ""), d
            said = _until(replans, lambda e: isinstance(e, ReplanEvent) and "25deg" in e.reason, 10.0)
            assert said.units == ["truck"] and "built" in said.reason, said
        finally:
            sub.undeclare()
