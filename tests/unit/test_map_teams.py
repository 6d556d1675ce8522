"""The map's model of teams: put and dissolved, the lead's track grown from its reports, in deltas, snapshots
and merged deltas."""

from __future__ import annotations

import pytest
from pfp_clients.map.model import MapModel, merge_deltas
from pfp_clients.map.samples import StateSeen, TeamSeen

from pfp_service.wire import UnitState
from pfp_service.wire.messages import TeamUpdate

pytestmark = pytest.mark.unit


def test_a_team_its_lead_track_and_its_dissolution_reach_the_page() -> None:
    m = MapModel()
    m.apply([TeamSeen("alpha", TeamUpdate(lead="r1", follow=["m1"], corridor_m=16.0))], 0.0)
    first = m.take_delta(0.0)
    assert (
        first is not None
        and first["teams"]["alpha"]["lead"] == "r1"
        and first["teams"]["alpha"]["track"] == []
    )
    m.apply([StateSeen("r1", UnitState(position=(float(x), 0.0))) for x in (0, 0.5, 1, 3)], 1.0)
    d = m.take_delta(1.0)
    assert d is not None
    assert [tuple(p) for p in d["teams"]["alpha"]["track"]] == [
        (0.0, 0.0),
        (1.0, 0.0),
        (3.0, 0.0),
    ]  # a point once the lead moved a sixteenth of 16 m
    m.apply([StateSeen("x", UnitState(position=(9.0, 9.0)))], 2.0)
    assert "teams" not in (m.take_delta(2.0) or {})  # not a member: the team is not redrawn
    assert m.snapshot(2.0)["teams"]["alpha"]["follow"] == ["m1"]
    m.apply([TeamSeen("alpha", None)], 3.0)
    gone = m.take_delta(3.0)
    assert gone is not None and gone["teams_removed"] == ["alpha"] and m.snapshot(3.0)["teams"] == {}
    merged = merge_deltas(first, gone)
    assert "teams" not in merged and merged["teams_removed"] == ["alpha"]
    again = merge_deltas(gone, first)
    assert "teams_removed" not in again and "alpha" in again["teams"]
