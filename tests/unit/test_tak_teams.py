"""``pfp tak`` and teams: a member's marker says its team and roles in its remarks; a dissolved team's members no
longer do, and a team the wire refuses is ignored with a line to the log."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from pfp_clients.tak.state import BridgeSettings, BridgeState

from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m

pytestmark = pytest.mark.unit

ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=87.5)
T0 = 1_700_000_000.0


def _remarks(s: BridgeState, unit: str, t: float) -> str:
    d = m.Direction(unit=unit, status=m.DirectionStatus.EN_ROUTE, vector=(0.0, 1.0), distance_to_goal=100.0)
    (marker,) = s.on_direction(keys.unit_direction("m", unit), m.encode(d), t).cot
    text = ET.fromstring(marker).find("detail/remarks")
    assert text is not None and text.text is not None
    return text.text


def test_a_team_members_marker_names_its_team_and_roles_until_the_team_is_dissolved() -> None:
    logged: list[str] = []
    s = BridgeState(BridgeSettings(mission="m", origin=ORIGIN, rate_s=1.0), logged.append)
    for u in ("r1", "m1", "x"):
        s.on_state(keys.unit_state("m", u), m.encode(m.UnitState(position=(0.0, 0.0))))
    team = m.TeamUpdate(lead="r1", follow=["m1"], controller="m1", robots=["r1"], members=["x"])
    s.on_team(keys.team("m", "alpha"), m.encode(team))
    assert "; team alpha: lead, robot" in _remarks(s, "r1", T0)
    assert _remarks(s, "m1", T0).split("; ")[3] == "team alpha: follow, controller"
    assert "team alpha: member" in _remarks(s, "x", T0)
    s.on_team(keys.team("m", "bravo"), b'{"lead": "q", "follow": ["q"]}')  # refused by the wire's checks
    assert logged and logged[-1].startswith("ignored team bravo:")
    s.on_team(keys.team("m", "alpha"), None)
    assert "team" not in _remarks(s, "r1", T0 + 10.0)
