"""Peers of one mission over another terrain are a conflict: the node tells the world, the world decides (issue 32)."""

from __future__ import annotations

import threading

import pytest

from pfp_service.node.duplicates import Peers
from pfp_service.wire import ConflictEvent
from pfp_service.wire.messages import TerrainInfo
from pfp_service.world.events import PeerTerrain, WorldSettings
from pfp_service.world.world import World

pytestmark = pytest.mark.unit


def _info(sha: str, name: str = "ridge.tif") -> TerrainInfo:
    return TerrainInfo(
        file=name,
        sha256=sha * 64,
        south=36.4,
        west=-84.4,
        north=36.7,
        east=-84.1,
        resolution_m=74.0,
        unit="foot",
    )


def _peers(mine: TerrainInfo | None) -> tuple[Peers, list[object]]:
    told: list[object] = []
    p = Peers("m1", "p1", True, threading.Lock(), told.append)
    p.terrain = mine
    return p, told


def _conflicts(told: list[object]) -> list[ConflictEvent]:
    w = World(WorldSettings(mission="m1", planner_id="p1", cluster=True))
    out = w.apply(told, 0.0)  # type: ignore[arg-type]
    return [e for e in out.events if isinstance(e, ConflictEvent)]


def test_a_peer_over_another_terrain_is_flagged_once_and_one_over_the_same_never() -> None:
    p, told = _peers(_info("a"))
    p.on_terrain("p2", _info("a"))
    assert _conflicts(told) == []
    told.clear()
    p.on_terrain("p3", _info("b", "other.tif"))
    p.on_terrain("p3", _info("b", "other.tif"))  # asked every second: told once
    assert len(told) == 1 and isinstance(told[0], PeerTerrain)
    (ev,) = _conflicts(told)
    assert ev.planner == "p1" and ev.other == "p3"
    assert "other.tif" in ev.reason and "ridge.tif" in ev.reason and "m1" in ev.reason
    told.clear()
    p.on_terrain("p3", _info("c"))  # and again when it changes terrain
    assert len(_conflicts(told)) == 1


def test_a_peer_on_flat_ground_conflicts_with_a_planner_over_terrain_and_both_flat_do_not() -> None:
    p, told = _peers(_info("a"))
    p.on_terrain("p2", None)
    (ev,) = _conflicts(told)
    assert "no terrain" in ev.reason
    flat, told = _peers(None)
    flat.on_terrain("p2", None)
    assert _conflicts(told) == []
