"""``pfp map`` and keep-out zones: the model's deltas (unit), and in a real Chromium an operator drawing
a polygon and a circle with ``--allow-edit`` that reach the planner, a zone put elsewhere drawn, and
one deleted from the page (browser)."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
import uuid

import pytest
from pfp_clients.map.model import MapModel, merge_deltas
from pfp_clients.map.samples import WorldSeen, ZoneSeen

from pfp_service.wire import WorldSnapshot, keys
from pfp_service.wire.messages import ZoneCircle, ZoneSummary, ZoneUpdate
from tests.browser.test_map_browser import playwright  # noqa: F401 -- the fixture, shared

SQUARE = ZoneUpdate(polygon=[[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0), (0.0, 0.0)]], ttl_s=30.0)


@pytest.mark.unit
def test_the_model_shows_zones_put_from_the_world_and_removed_and_expired():
    mm = MapModel()
    mm.apply([ZoneSeen("sq", SQUARE)], 100.0)
    d = mm.take_delta(100.0)
    assert d is not None and d["zones"]["sq"]["polygon"][0][2] == (10.0, 10.0)
    assert d["zones"]["sq"]["expires_at"] == 130.0
    world = WorldSnapshot(
        planner="p",
        mission="m",
        units=[],
        threats=[],
        zones=[ZoneSummary(id="c", zone=ZoneUpdate(circle=ZoneCircle(centre=(5.0, 5.0), radius_m=3.0)))],
        zones_total=1,
    )
    mm.apply([WorldSeen(world)], 101.0)
    assert mm.snapshot(101.0)["zones"]["c"]["circle"] == {"centre": (5.0, 5.0), "radius_m": 3.0}
    mm.take_delta(101.0)
    mm.apply([ZoneSeen("c", None)], 102.0)
    assert mm.take_delta(102.0)["zones_removed"] == ["c"]  # type: ignore[index]
    assert mm.take_delta(130.0)["zones_removed"] == ["sq"]  # type: ignore[index]  # its TTL ran out
    assert not mm.zones and not mm.zone_updates
    merged = merge_deltas({"now": 1, "zones": {"a": {"id": "a"}}}, {"now": 2, "zones_removed": ["a"]})
    assert "zones" not in merged and merged["zones_removed"] == ["a"]


@pytest.mark.browser
@pytest.mark.alone
def test_a_zone_drawn_on_the_map_with_allow_edit_reaches_the_planner(playwright, tmp_path, mission):  # noqa: F811
    from tests.browser.test_map_browser import map_process, page_at, running
    from tests.zenoh_util import Inbox, client, planner_process, put_json

    team = tmp_path / "team.yaml"
    team.write_text("units:\n  - {id: a1, kind: unmanned, start: [0, 20], goal: [80, 20], speed_mps: 1.0}\n")
    with (
        planner_process(mission=mission) as (endpoint, _planner),
        client(endpoint) as s,
        running(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission, "--duration-s", "300"
        ),
        map_process(endpoint, mission, "--allow-edit") as url,
        page_at(playwright, url) as page,
    ):
        zones = Inbox(s, keys.zones(mission))
        replans = Inbox(s, keys.event(mission, "replan"))
        page.wait("() => document.querySelector(`[data-unit='a1']`) !== null")
        page.view(-5, -5, 85, 65)

        # a wall across the unit's way, drawn corner by corner
        page.page.fill("#new-id", "wall")
        page.page.click("#zone-draw")
        for x, y in ((40, 5), (46, 5), (46, 35), (40, 35)):
            page.click_at(x, y)
        page.page.click("#zone-finish")
        body = zones.get(timeout=5, where=lambda z: z is not None)
        (ring,) = body["polygon"]
        assert len(ring) == 5 and ring[0] == ring[-1]
        assert [round(v) for v in ring[2]] == [46, 35]  # the corners as clicked, in mission metres
        replan = replans.get(timeout=5, where=lambda e: "zone wall put" in e["reason"])
        assert "a1" in replan["units"]  # the planner re-directed the unit round it
        page.wait("() => pfpMap.zones.has('wall')", timeout_s=5)  # drawn back from the planner's key

        # the planner holds it
        world = [r for r in s.get(keys.worlds(mission), timeout=5) if r.ok is not None]
        held = json.loads(world[0].ok.payload.to_bytes())["zones"]
        assert [z["id"] for z in held] == ["wall"]

        # a circle: centre, then edge
        page.page.fill("#new-id", "pond")
        page.page.click("#zone-circle")
        page.click_at(20, 50)
        page.click_at(26, 50)
        body = zones.get(timeout=5, where=lambda z: z is not None and "circle" in z and z["circle"])
        assert body["circle"]["radius_m"] == pytest.approx(6.0, abs=0.5)
        assert body["circle"]["centre"] == pytest.approx([20, 50], abs=0.5)
        page.wait("() => pfpMap.zones.has('pond')", timeout_s=5)

        # a zone put by someone else is drawn; the GeoJSON export has it
        put_json(s, keys.zone(mission, "other"), {"circle": {"centre": [70, 50], "radius_m": 4}})
        page.wait("() => pfpMap.zones.has('other')", timeout_s=5)
        # every zone is labelled on the map by its id, without hovering it
        labels = page.js("() => [...document.querySelectorAll('.zone-label')].map((e) => e.textContent)")
        assert "no-go other" in labels and "no-go pond" in labels, labels

        # select the wall by clicking inside it and delete it from the page
        page.click_at(43, 20)
        page.wait("() => !document.querySelector('#zone-panel').hidden")
        assert page.js("() => pfpMap.selectedZone") == "wall"
        page.page.click("#zone-delete")
        zones.get(timeout=5, where=lambda z: z is None)
        page.wait("() => !pfpMap.zones.has('wall')", timeout_s=5)
        assert page.errors == []
        # editing refused without the header: the page's edits are the only way in
        req = urllib.request.Request(f"{url.rstrip('/')}/api/zone/x", data=b"{}", method="PUT")
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(req, timeout=5)
        assert refused.value.code == 403


@pytest.fixture
def mission() -> str:
    return "mapz" + uuid.uuid4().hex[:8]


@pytest.mark.unit
def test_the_geojson_export_has_the_zones_as_keep_out_polygons():
    from pfp_clients.map.server import MapOptions, MapServer

    from pfp_service.geo import Origin
    from pfp_service.geojson import zones_from_geojson

    origin = Origin(lat=58.4105, lon=15.6213, alt=87.5)
    srv = MapServer(None, MapOptions(mission="m", origin=origin))
    srv.model.apply(
        [
            ZoneSeen("sq", SQUARE),
            ZoneSeen("c", ZoneUpdate(circle=ZoneCircle(centre=(50.0, 0.0), radius_m=5.0))),
        ],
        0.0,
    )
    resp = _run(srv._geojson(None))  # type: ignore[arg-type]
    fc = json.loads(resp.body)
    kept = [f for f in fc["features"] if f["properties"]["kind"] == "keep_out"]
    assert sorted(f["properties"]["id"] for f in kept) == ["c", "sq"]
    back = {z.id: z for z in zones_from_geojson({"type": "FeatureCollection", "features": kept}, origin)}
    assert back["sq"].area_m2() == pytest.approx(100.0, rel=1e-3)  # lon/lat kept to the centimetre
    assert back["c"].contains(50.0, 4.99)  # the circle's polygon holds the circle
    none = MapServer(None, MapOptions(mission="m"))
    assert _run(none._geojson(None)).status == 409  # type: ignore[arg-type]


def _run(coro):
    """Run a coroutine on a loop of its own thread (a browser test in the session may hold this one's)."""
    import asyncio
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, coro).result()
