"""A threat of another shape on the wire, as a user puts one: the planner steers round it, ``pfp status``
shows it, and a shape the planner does not know is refused on its key while the planner carries on."""

from __future__ import annotations

import re
import time
import uuid

import pytest

from tests.conftest import run_pfp
from tests.proc.test_serve import Unit
from tests.zenoh_util import Inbox, client, planner_process, put_json

pytestmark = pytest.mark.proc


def test_an_area_threat_is_planned_round_shown_and_an_unknown_shape_refused():
    mission = "s" + uuid.uuid4().hex[:10]
    with planner_process(mission=mission) as (endpoint, _), client(endpoint) as s:
        events = Inbox(s, f"mumt/{mission}/event/rejected")
        scout = Unit(s, mission, "scout", pos=(7.0, 0.0))  # beside the circle, which lies north of its way
        assert scout.report()["status"] == "no_goal"  # a round trip: the subscriber is in place by now
        put_json(s, f"mumt/{mission}/threat/cone", {"position": [5, 5], "shape": "cone"})
        ev = events.get(timeout=15)
        assert ev["field"] == "$.shape" and "unknown threat shape 'cone'" in ev["reason"]

        put_json(
            s,
            f"mumt/{mission}/threat/scouted",
            {"position": [10, 0.5], "shape": "area", "params": {"radius_m": 2}},
        )
        put_json(s, f"mumt/{mission}/unit/scout/goal", {"position": [20, 0]})
        deadline = time.monotonic() + 30
        while True:  # once the planner holds the threat the unit is steered off the straight line east
            d = scout.report()
            if d["vector"][1] < -0.05 or time.monotonic() > deadline:
                break
        assert d["vector"][1] < -0.05, d  # pushed south, away from the circle
        r = run_pfp("status", "--connect", endpoint, "--mission", mission, timeout=60)
        assert r.returncode == 0, r.stderr
        assert re.search(r"^scouted\s+\(10\.0, 0\.5\)\s+area 2 m\s+", r.stdout, re.M), r.stdout
        assert "cone" not in r.stdout
