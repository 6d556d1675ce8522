"""A threat put over real terrain re-directs the units it sees, not the ones the ground hides (issue 32).

A planner (``PlannerNode``, in this process) serves over the Jacksboro DEM
(``terrain_data``, real ridge-and-valley ground) on a loopback Zenoh router;
a client reports two units standing 1.5 km from where a threat will be put,
one that the threat sees along its whole corridor and one that a ridge hides
from it, each chosen by an exact line of sight (``exact_lowest_visible_height``,
not the sweep the planner uses).  The threat's window is computed off the
loop (``node.terrain.Sights``); the replan it brings names the seen unit
only, and the hidden unit gets no fresh direction.
"""

from __future__ import annotations

import math
import queue

import numpy as np
import pytest
import zenoh

from pfp_service.node.config import ServeConfig, zenoh_config
from pfp_service.node.node import PlannerNode
from pfp_service.node.terrain import placed
from pfp_service.terrain.live import load
from pfp_service.terrain.viewshed import exact_lowest_visible_height
from pfp_service.wire import (
    Direction,
    Goal,
    ReplanEvent,
    ThreatUpdate,
    UnitState,
    decode,
    decode_event,
    encode,
    keys,
)
from pfp_service.world.reach import WIDE_REACH
from tests.terrain_data import write_geographic
from tests.zenoh_util import client, free_port

pytestmark = pytest.mark.net

MISSION = "liveterrain"
RINGS_M = (1500.0, 2000.0, 2500.0)
SIGMA_M = 1500.0  # blind, the threat reaches both units
CORRIDOR_CELLS = 3  # a unit's goal, this many cells north of it
EYE_M = 2.0


def _pick(ground) -> dict[str, tuple[float, float]]:
    """A unit the threat at (0, 0) sees all along its corridor north, and one it sees nowhere near (exact rays).

    Nowhere near: not on the box a deliberating unit is judged by either
    (``reach.WIDE_REACH`` of its corridor's length round it), since in
    this tier no worker runs its jobs.
    """
    g = ground.grid
    c = g.cell_m
    obs = (round(-g.y0_m / c), round(-g.x0_m / c))
    height = ground.unit.height_m
    pad = math.ceil(WIDE_REACH * CORRIDOR_CELLS) + 1
    got: dict[str, tuple[float, float]] = {}
    for ring in RINGS_M:
        for a in range(0, 360, 5):
            i = round((ring * math.sin(math.radians(a)) - g.x0_m) / c)
            k = round((ring * math.cos(math.radians(a)) - g.y0_m) / c)
            where = (g.x0_m + i * c, g.y0_m + k * c)
            corridor = np.array([[k + d, i] for d in range(CORRIDOR_CELLS + 1)])
            if "seen" not in got and np.all(
                exact_lowest_visible_height(g.z, obs, EYE_M, corridor, c, c) <= 0
            ):
                got["seen"] = where
            box = np.array(
                [
                    [kk, ii]
                    for kk in range(k - pad, k + CORRIDOR_CELLS + pad + 1)
                    for ii in range(i - pad, i + pad + 1)
                ]
            )
            if "hidden" not in got and np.all(
                exact_lowest_visible_height(g.z, obs, EYE_M, box, c, c) >= 5 * height
            ):
                got["hidden"] = where
    assert set(got) == {"seen", "hidden"}, got
    return got


def _until(q: queue.Queue, want, timeout: float):
    import time

    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise AssertionError("timed out")
        got = q.get(timeout=left)
        if want(got):
            return got


def test_a_threat_put_over_real_terrain_redirects_the_unit_it_sees_and_not_the_hidden_one(
    tmp_path, monkeypatch
):
    from pfp_service.node.previews import PreviewService

    # previews are not under test, and a net-tier test starts no worker process: the node waits for none
    real_wait = PreviewService.wait_ready
    monkeypatch.setattr(PreviewService, "wait_ready", lambda self, timeout_s=0.0: real_wait(self, 0.0))
    dem = str(write_geographic(tmp_path / "jacksboro.tif"))
    ep = f"tcp/127.0.0.1:{free_port()}"
    cfg = placed(ServeConfig(mission=MISSION, listen=[ep], terrain=dem, lookahead=0, unit_stale_s=120.0))
    ground = load(dem, cfg.origin, cfg.bounds_tuple(), cfg.terrain_unit)
    units, cell = _pick(ground), ground.grid.cell_m
    session = zenoh.open(zenoh_config(cfg))
    node = PlannerNode(session, cfg)
    try:
        node.start()
        with client(ep) as c:
            directions: queue.Queue = queue.Queue()
            replans: queue.Queue = queue.Queue()
            subs = [
                c.declare_subscriber(
                    keys.unit_directions(MISSION),
                    lambda s: directions.put(decode(Direction, s.payload.to_bytes())),
                ),
                c.declare_subscriber(
                    keys.event(MISSION, "replan"), lambda s: replans.put(decode_event(s.payload.to_bytes()))
                ),
            ]
            for uid, (x, y) in units.items():
                c.put(keys.unit_goal(MISSION, uid), encode(Goal(position=(x, y + CORRIDOR_CELLS * cell))))
                c.put(keys.unit_state(MISSION, uid), encode(UnitState(position=(x, y), seq=1)))
            guided: set[str] = set()
            while guided != set(units):
                d = _until(directions, lambda d: d.status.value != "no_goal", 120.0)
                guided.add(d.unit)
            threat = ThreatUpdate(position=(0.0, 0.0), sigma_range=SIGMA_M, sigma_lateral=SIGMA_M)
            c.put(keys.threat(MISSION, "ridge"), encode(threat))
            replan = _until(replans, lambda e: isinstance(e, ReplanEvent) and "ridge" in e.reason, 60.0)
            assert replan.units == ["seen"], (replan, units)
            # the hidden unit's direction was not sent again for the threat: only pushes to the seen one
            while not directions.empty():
                directions.get_nowait()
            c.put(keys.unit_state(MISSION, "seen"), encode(UnitState(position=units["seen"], seq=2)))
            got = _until(directions, lambda d: d.seq == 2, 30.0)
            assert got.unit == "seen" and got.threat_level > 0.0
            pushed = []
            while not directions.empty():
                pushed.append(directions.get_nowait().unit)
            assert "hidden" not in pushed, pushed
            for s in subs:
                s.undeclare()
    finally:
        node.stop()
        session.close()
