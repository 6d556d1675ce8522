"""``pfp map`` draws teams, in a real headless Chromium against a real planner: a line from the lead to its
follower, the controller's radio circle (its radius in metres on the map), and the cleared corridor (the lead's
track, as wide on screen as ``corridor_m`` at the zoom shown); a team dissolved leaves nothing drawn."""

from __future__ import annotations

import math

import pytest

from pfp_service.wire import keys
from tests.browser.test_map_browser import map_process, mission, page_at, playwright  # noqa: F401 - fixtures
from tests.zenoh_util import client, planner_process, put_json

pytestmark = [pytest.mark.browser, pytest.mark.alone]


def test_the_map_draws_a_team_s_link_radio_circle_and_cleared_corridor(playwright, mission) -> None:  # noqa: F811
    team = {
        "lead": "r1",
        "follow": ["m1"],
        "controller": "m1",
        "robots": ["r1"],
        "radio_range_m": 60.0,
        "corridor_m": 6.0,
    }
    with (
        planner_process(mission=mission) as (endpoint, _planner),
        client(endpoint) as s,
        map_process(endpoint, mission) as url,
        page_at(playwright, url) as page,
    ):
        put_json(s, keys.team(mission, "alpha"), team)
        page.wait("() => pfpTeams.teams.has('alpha')")
        put_json(s, keys.unit_state(mission, "m1"), {"position": [0.0, 0.0], "kind": "manned"})
        for i in range(
            12
        ):  # the lead drives east 2 m a report (each seen before the next); the follower stays
            x = 10.0 + 2 * i
            put_json(s, keys.unit_state(mission, "r1"), {"position": [x, 0.0], "kind": "unmanned"})
            page.wait(f"() => pfpTeams.teams.get('alpha').track.length === {i + 1}")
        page.wait(
            "() => pfpTeams.teams.get('alpha').track.length >= 12 && pfpMap.units.get('r1').data.position[0] >= 32"
        )
        page.view(-70, -70, 70, 70)
        page.wait("() => pfpTeams.drawn.get('alpha').links.length === 1")
        got = page.js(
            """() => {
              const d = pfpTeams.drawn.get('alpha');
              const link = d.links[0].getLatLngs().map(toMetres);
              const edge = toMetres(L.latLng(d.circle.getBounds().getNorth(), d.circle.getLatLng().lng));
              return {
                link,
                centre: toMetres(d.circle.getLatLng()),
                north: edge,
                track: d.corridor.getLatLngs().map(toMetres),
                weight: d.corridorWeightPx,
                mpp: pfpTeams.metresPerPixel(),
              };
            }"""
        )
        (a, b) = got["link"]
        assert math.dist(a, (32.0, 0.0)) < 0.01 and math.dist(b, (0.0, 0.0)) < 0.01, got["link"]
        assert math.dist(got["centre"], (0.0, 0.0)) < 0.01
        assert got["north"][1] == pytest.approx(60.0, abs=0.5)  # the radio circle reaches 60 m north
        assert len(got["track"]) == 12 and math.dist(got["track"][-1], (32.0, 0.0)) < 0.01
        assert got["weight"] * got["mpp"] == pytest.approx(6.0, rel=0.02)  # the corridor, 6 m wide on screen
        s.delete(keys.team(mission, "alpha"))
        page.wait("() => !pfpTeams.teams.has('alpha') && !pfpTeams.drawn.has('alpha')")
        assert page.js("() => pfpTeams.layer.getLayers().length") == 0
        assert page.errors == []
