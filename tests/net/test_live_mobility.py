"""A goal's mobility class over Zenoh, over real terrain: each unit plans round its own slope barriers (issue 32).

A planner (``PlannerNode``, in this process, ``--terrain-unit foot``) serves
over the Jacksboro DEM on a loopback Zenoh router.  Two units are sent to the
same goal on ground steeper than a wheeled vehicle climbs (17 degrees) and
gentler than a soldier's limit (30): the soldier is guided, the wheeled unit
is ``trapped`` with a reason naming the slope.  A third goal naming an unknown
class is rejected on ``$.mobility.class`` and the others carry on.  The same
with the classes named on the units' states instead: a state naming an
unknown class is rejected on the state's key, and a truck whose state turns
``tracked`` mid-route (31 degrees) is guided on at once.
"""

from __future__ import annotations

import contextlib
import queue
import time

import numpy as np
import pytest
import zenoh

from pfp_service.node.config import ServeConfig, zenoh_config
from pfp_service.node.node import PlannerNode
from pfp_service.node.terrain import placed
from pfp_service.terrain.barriers import barrier_cells
from pfp_service.terrain.live import load
from pfp_service.wire import (
    Direction,
    Goal,
    GoalMobility,
    RejectedEvent,
    UnitState,
    decode,
    decode_event,
    encode,
    keys,
)
from tests.terrain_data import write_geographic
from tests.zenoh_util import client, free_port

pytestmark = pytest.mark.net

MISSION = "livemobility"


def _places(ground, upper_deg: float = 30.0) -> tuple[tuple[float, float], tuple[float, float]]:
    """A goal on a cell a wheeled unit cannot enter and a soldier (or one climbing ``upper_deg``) can, and a
    start near it a wheeled unit can."""
    g = ground.grid
    c = g.cell_m
    wheeled, _ = barrier_cells(g, 17.0)
    foot, unknown = barrier_cells(g, upper_deg)
    ny, nx = wheeled.shape
    mid = np.array([ny // 2, nx // 2])
    goals = np.argwhere(wheeled & ~foot & ~unknown)
    goals = goals[np.argsort(np.abs(goals - mid).sum(axis=1))]
    flat = ~wheeled & ~unknown
    for k, i in goals:
        for dk, di in ((-8, 0), (8, 0), (0, -8), (0, 8), (-12, -12), (12, 12)):
            kk, ii = k + dk, i + di
            if 0 <= kk < ny and 0 <= ii < nx and flat[max(kk - 1, 0) : kk + 2, max(ii - 1, 0) : ii + 2].all():
                centre = lambda a, b: (float(g.x0_m + (b + 0.5) * c), float(g.y0_m + (a + 0.5) * c))
                return centre(k, i), centre(kk, ii)
    raise AssertionError(f"no slope between 17 and {upper_deg:g} degrees on the DEM")


def _until(q: queue.Queue, want, timeout: float):
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise AssertionError("timed out")
        got = q.get(timeout=left)
        if want(got):
            return got


@contextlib.contextmanager
def _planner(tmp_path, monkeypatch, upper_deg: float = 30.0):
    """A planner over the Jacksboro DEM on a loopback router, and a client's queues of directions and rejections:
    ``(client, directions, rejected, (goal, start))``."""
    from pfp_service.node.previews import PreviewService

    real_wait = PreviewService.wait_ready  # previews are not under test: the node waits for no worker
    monkeypatch.setattr(PreviewService, "wait_ready", lambda self, timeout_s=0.0: real_wait(self, 0.0))
    dem = str(write_geographic(tmp_path / "jacksboro.tif"))
    ep = f"tcp/127.0.0.1:{free_port()}"
    cfg = placed(ServeConfig(mission=MISSION, listen=[ep], terrain=dem, lookahead=0, unit_stale_s=120.0))
    ground = load(dem, cfg.origin, cfg.bounds_tuple(), cfg.terrain_unit)
    assert ground.barriers(30) is ground.zones  # a soldier's goal over a foot planner: its own barriers
    places = _places(ground, upper_deg)
    session = zenoh.open(zenoh_config(cfg))
    node = PlannerNode(session, cfg)
    try:
        node.start()
        with client(ep) as c:
            directions: queue.Queue = queue.Queue()
            rejected: queue.Queue = queue.Queue()
            subs = [
                c.declare_subscriber(
                    keys.unit_directions(MISSION),
                    lambda s: directions.put(decode(Direction, s.payload.to_bytes())),
                ),
                c.declare_subscriber(
                    keys.event(MISSION, "rejected"),
                    lambda s: rejected.put(decode_event(s.payload.to_bytes())),
                ),
            ]
            try:
                _heard(c)
                yield c, directions, rejected, places
            finally:
                for s in subs:
                    s.undeclare()
    finally:
        node.stop()
        session.close()


def _heard(c: zenoh.Session, timeout: float = 60.0) -> None:
    """Until the planner answers its status through ``c``: a put before its subscriptions reached the client's
    session is dropped there (under load the start of the test raced them and timed out)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(r.ok is not None for r in c.get(f"mumt/{MISSION}/planner/*/status", timeout=1.0)):
            return
        time.sleep(0.05)
    raise AssertionError("the planner never answered its status")


def _foot_goes_and_wheeled_is_trapped(directions: queue.Queue) -> None:
    """The first verdicts of the soldier and the truck sent up the one slope: each by its own class."""
    seen: dict[str, Direction] = {}
    while set(seen) != {"soldier", "truck"}:
        d = _until(directions, lambda d: d.status.value != "no_goal" and d.unit != "bad", 120.0)
        seen[d.unit] = d
    assert seen["soldier"].status.value == "en_route", seen["soldier"]
    assert seen["truck"].status.value == "trapped", seen["truck"]
    assert "slope>17deg" in (seen["truck"].reason or "")


def test_a_foot_and_a_wheeled_unit_sent_up_one_slope_get_their_own_verdicts_and_a_bad_class_is_refused(
    tmp_path, monkeypatch
):
    with _planner(tmp_path, monkeypatch) as (c, directions, rejected, (goal, start)):
        classes = {"soldier": "foot", "truck": "wheeled", "bad": "hovercraft"}
        for uid, kind in classes.items():
            body = Goal(position=goal, tolerance=1.0, mobility=GoalMobility(kind=kind))
            c.put(keys.unit_goal(MISSION, uid), encode(body))
            c.put(keys.unit_state(MISSION, uid), encode(UnitState(position=start, seq=1)))
        refused = _until(rejected, lambda e: isinstance(e, RejectedEvent), 60.0)
        assert refused.key == keys.unit_goal(MISSION, "bad") and refused.field == "$.mobility.class"
        _foot_goes_and_wheeled_is_trapped(directions)


def test_classes_named_on_the_states_plan_each_unit_and_a_class_changed_mid_route_replans_it(
    tmp_path, monkeypatch
):
    with _planner(tmp_path, monkeypatch) as (c, directions, rejected, (goal, start)):
        classes = {"soldier": "foot", "truck": "wheeled", "bad": "hovercraft"}
        for uid, kind in classes.items():
            state = UnitState(position=start, seq=1, mobility=GoalMobility(kind=kind))
            c.put(keys.unit_state(MISSION, uid), encode(state))
            c.put(keys.unit_goal(MISSION, uid), encode(Goal(position=goal, tolerance=1.0)))
        refused = _until(rejected, lambda e: isinstance(e, RejectedEvent), 60.0)
        assert refused.key == keys.unit_state(MISSION, "bad") and refused.field == "$.mobility.class"
        assert "hovercraft" in refused.reason
        _foot_goes_and_wheeled_is_trapped(directions)
        tracked = UnitState(position=start, seq=2, mobility=GoalMobility(kind="tracked"))
        c.put(keys.unit_state(MISSION, "truck"), encode(tracked))
        d = _until(directions, lambda d: d.unit == "truck" and d.seq == 2, 60.0)
        assert d.status.value == "en_route", d
