"""``pfp handheld --nmea --origin``: its origin against the planner's, checked once connected.

A GPS handheld turns lat/lon into metres from ``--origin``; from any other
origin than the planner's every position it sends is off by the distance
between the two.  The link asks the planner's status, and when the origins
differ it sends no position and the screen says which origin to use.
"""

from __future__ import annotations

import asyncio
import queue
import time
import uuid

import pytest
from pfp_clients.handheld import HandheldApp
from pfp_clients.handheld_link import OriginChecked, RetryingLink
from pfp_clients.handheld_model import HandheldModel, Settings
from pfp_clients.nmea import LocalFrame

from pfp_service.node.config import client_zenoh_config
from pfp_service.wire import UnitState, keys
from tests.zenoh_util import Inbox, client, planner_process

PLANNER_ORIGIN = (48.0, 11.0)


@pytest.fixture(scope="module")
def planner():
    mission = "ho" + uuid.uuid4().hex[:10]
    with planner_process("--origin", "48,11", mission=mission) as (endpoint, proc):
        yield endpoint, mission, proc


def _link(endpoint: str, mission: str, unit: str, origin: tuple[float, float]) -> RetryingLink:
    frame = LocalFrame(*origin)
    return RetryingLink(lambda: client_zenoh_config([endpoint]), endpoint, mission, unit, origin=frame.origin)


def _checked(link: RetryingLink, timeout: float = 15.0) -> OriginChecked:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            item = link.inbox.get(timeout=0.2)
        except queue.Empty:
            continue
        if isinstance(item, OriginChecked):
            return item
    raise AssertionError(f"no origin verdict within {timeout} s")


def _states_after_publish(link: RetryingLink, inbox: Inbox, n: int = 5) -> int:
    for i in range(n):
        link.publish_state(UnitState(position=(1.0, 2.0), seq=i + 1))
        time.sleep(0.05)
    time.sleep(0.5)
    got = 0
    while not inbox.q.empty():
        inbox.q.get_nowait()
        got += 1
    return got


@pytest.mark.proc
def test_another_origin_sends_no_position_and_says_which_to_use(planner):
    endpoint, mission, _ = planner
    with client(endpoint) as s:
        states = Inbox(s, keys.shard_state(mission, "far"))
        link = _link(endpoint, mission, "far", (48.5, 11.0))  # ~55 km north of the planner's
        try:
            verdict = _checked(link)
            assert not verdict.ok and link.origin_refused
            assert "48,11" in verdict.text and "differs" in verdict.text and "m away" in verdict.text
            assert "positions not sent" in verdict.text
            assert _states_after_publish(link, states) == 0
        finally:
            link.close()


@pytest.mark.proc
def test_the_planners_own_origin_is_checked_and_positions_go_out(planner):
    endpoint, mission, _ = planner
    with client(endpoint) as s:
        states = Inbox(s, keys.shard_state(mission, "near"))
        link = _link(endpoint, mission, "near", PLANNER_ORIGIN)
        try:
            verdict = _checked(link)
            assert verdict.ok and verdict.text == "" and not link.origin_refused
            assert _states_after_publish(link, states) == 5
        finally:
            link.close()


@pytest.mark.proc
def test_the_screen_shows_the_refusal_and_goes_stale(planner):
    endpoint, mission, _ = planner

    async def scenario():
        link = _link(endpoint, mission, "screen", (47.0, 11.0))
        try:
            model = HandheldModel(Settings(unit="screen", walk=False, gps=True), (0.0, 0.0), time.monotonic())
            app = HandheldApp(model, link, mission=mission, publish_hz=5.0, source="nmea")
            async with app.run_test(size=(60, 20)) as pilot:
                deadline = time.monotonic() + 15.0
                while "positions not sent" not in app.last_view.note:
                    assert time.monotonic() < deadline, app.last_view.note
                    await pilot.pause(0.1)
                assert app.last_view.stale and "--origin 48,11" in app.last_view.note
        finally:
            link.close()

    asyncio.run(scenario())


@pytest.mark.unit
def test_the_model_refuses_until_the_origins_agree():
    model = HandheldModel(Settings(unit="u", walk=False, gps=True), (0.0, 0.0), 0.0)
    model.on_origin(False, "positions not sent: 47,11 differs")
    assert model.stale(0.1) and model.view(0.1).note == "positions not sent: 47,11 differs"
    model.on_origin(True, "")
    assert not model.stale(0.1) and model.view(0.1).note == ""
    model.on_origin(
        True, "the planner of mission 'm' has no origin: its metres are taken from --origin 47,11"
    )
    assert "has no origin" in model.view(0.1).note and not model.stale(0.1)
