"""The handheld speaks a soldier's coordinates, and Ctrl-C quits it with 130.

* ``coords.parse_point`` reads back what ``Coords`` shows: degrees with hemisphere
  letters and MGRS references (the ``mgrs`` library) land within a metre and a half
  of the point shown (the text keeps 5 decimals, 1 m grid squares); bare ``LAT,LON``
  stays metres, and lat/lon without an origin is refused with the reason.
* Against a real planner with an origin, the app learns it, shows its position in
  lat/lon or MGRS, takes a goal typed as an MGRS reference, and quits on Ctrl-C
  (a key in a raw terminal, not a signal) with 130.
"""

from __future__ import annotations

import asyncio
import time
import uuid

import pytest

from pfp_service.coords import Coords, parse_point
from pfp_service.geo import Origin

ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=0.0)
SIZE = (50, 20)


@pytest.mark.unit
@pytest.mark.parametrize("style", ["latlon", "mgrs"])
@pytest.mark.parametrize("point", [(0.0, 0.0), (300.0, 260.0), (-1200.5, 40.0), (2500.0, -3100.0)])
def test_what_coords_shows_parses_back_to_the_point(style, point):
    shown = Coords.choose(style, ORIGIN).point(point, offset=False)
    got = parse_point(shown, ORIGIN)
    assert isinstance(got, tuple), got
    assert abs(got[0] - point[0]) < 1.5 and abs(got[1] - point[1]) < 1.5, (shown, got)


@pytest.mark.unit
def test_parse_point_forms_and_refusals():
    assert parse_point("120,80", None) == (120.0, 80.0)
    assert parse_point(" 58.41 , 15.62 ", ORIGIN) == (58.41, 15.62)  # bare numbers are metres
    spaced = parse_point("33V WE 36600 74844", ORIGIN)
    squeezed = parse_point("33VWE3660074844", ORIGIN)
    assert isinstance(spaced, tuple) and spaced == squeezed
    degrees = parse_point("58.4105°N, 15.6213°E", ORIGIN)
    assert isinstance(degrees, tuple) and max(map(abs, degrees)) < 0.01
    assert "needs the mission origin" in str(parse_point("58.4N 15.6E", None))
    assert "needs the mission origin" in str(parse_point("33VWE 36600 74844", None))
    assert "not a latitude and longitude" in str(parse_point("91N 15E", ORIGIN))
    assert "expected X,Y" in str(parse_point("north", ORIGIN))
    assert "expected finite" in str(parse_point("nan,1", ORIGIN))


@pytest.fixture(scope="module")
def geo_planner():
    from tests.zenoh_util import planner_process

    mission = "hc" + uuid.uuid4().hex[:10]
    with planner_process("--origin", f"{ORIGIN.lat},{ORIGIN.lon}", mission=mission) as (endpoint, _proc):
        yield endpoint, mission


async def _until(pilot, pred, what: str, timeout: float = 15.0):
    deadline = time.monotonic() + timeout
    while not (value := pred()):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await pilot.pause(0.05)
    return value


@pytest.mark.proc
@pytest.mark.parametrize("style", ["latlon", "mgrs"])
def test_the_app_learns_the_origin_shows_and_takes_its_coordinates_and_quits_on_ctrl_c(geo_planner, style):
    pytest.importorskip("textual")
    from pfp_clients.handheld import HandheldApp
    from pfp_clients.handheld_link import RetryingLink, client_config
    from pfp_clients.handheld_model import HandheldModel, Settings

    endpoint, mission = geo_planner
    uid = f"coords-{style}"
    goal = (20.0, -15.0)
    typed = Coords.choose("mgrs", ORIGIN).point(goal, offset=False)  # typed as a soldier reads a map

    async def scenario() -> object:
        link = RetryingLink(lambda: client_config([endpoint]), endpoint, mission, uid)
        try:
            model = HandheldModel(Settings(unit=uid, walk=False), (0.0, 0.0), time.monotonic())
            app = HandheldApp(model, link, mission=mission, publish_hz=5.0, coords=style)
            async with app.run_test(size=SIZE) as pilot:
                shown = Coords.choose(style, ORIGIN).point((0.0, 0.0), offset=False)
                pos = lambda: str(app.query_one("#pos").content)
                await _until(pilot, lambda: shown in pos(), f"the position as {shown!r}")
                await pilot.press("g")
                await pilot.pause(0.2)
                field = app.screen.query_one("#goal")
                field.value = typed
                await pilot.press("enter")
                await _until(pilot, lambda: app.model.goal is not None, "the typed goal")
                gx, gy = app.model.goal
                assert abs(gx - goal[0]) < 1.5 and abs(gy - goal[1]) < 1.5, (typed, app.model.goal)
                await _until(
                    pilot,
                    lambda: app.last_view is not None and app.last_view.status_label == "EN ROUTE",
                    "guidance to the typed goal",
                )
                await pilot.press("ctrl+c")
                await _until(
                    pilot, lambda: app.return_value is not None or not app.is_running, "the app to end"
                )
            return app.return_value
        finally:
            link.close()

    assert asyncio.run(scenario()) == 130


@pytest.mark.proc
def test_a_goal_given_in_mgrs_at_start_is_set_once_the_planners_origin_is_learnt(geo_planner):
    """``pfp handheld --goal "33VWE ..."`` without ``--origin``: the goal waits for the planner's origin."""
    pytest.importorskip("textual")
    from pfp_clients.handheld import HandheldApp
    from pfp_clients.handheld_link import RetryingLink, client_config
    from pfp_clients.handheld_model import HandheldModel, Settings

    endpoint, mission = geo_planner
    uid = "coords-start"
    goal = (-25.0, 30.0)
    typed = Coords.choose("mgrs", ORIGIN).point(goal, offset=False)

    async def scenario() -> tuple[float, float] | None:
        link = RetryingLink(lambda: client_config([endpoint]), endpoint, mission, uid)
        try:
            model = HandheldModel(Settings(unit=uid, walk=False), (0.0, 0.0), time.monotonic())
            app = HandheldApp(model, link, mission=mission, publish_hz=5.0, goal_text=typed)
            async with app.run_test(size=SIZE) as pilot:
                # never a goal before the origin it is read in (the origin may already be learnt)
                assert app.model.goal is None or app.origin is not None
                await _until(pilot, lambda: app.model.goal is not None, "the goal, once the origin is learnt")
                await _until(
                    pilot,
                    lambda: app.last_view is not None and app.last_view.status_label == "EN ROUTE",
                    "guidance to it",
                )
                return app.model.goal
        finally:
            link.close()

    got = asyncio.run(scenario())
    assert got is not None and abs(got[0] - goal[0]) < 1.5 and abs(got[1] - goal[1]) < 1.5, (typed, got)
