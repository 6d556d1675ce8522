"""Peers of one mission over another terrain are a conflict (``Peers.on_terrain``, issue 32)."""

from __future__ import annotations

import threading

import pytest

from pfp_service.node.twins import Peers
from pfp_service.wire import ConflictEvent
from pfp_service.wire.messages import TerrainInfo

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


def _peers(mine: TerrainInfo | None) -> tuple[Peers, list[int]]:
    woken: list[int] = []
    p = Peers("m1", "p1", True, threading.Lock(), lambda _inp: None, lambda: woken.append(1))
    p.terrain = mine
    return p, woken


def test_a_peer_over_another_terrain_is_flagged_once_and_one_over_the_same_never() -> None:
    p, woken = _peers(_info("a"))
    p.on_terrain("p2", _info("a"))
    assert p.take_events() == [] and not woken
    p.on_terrain("p3", _info("b", "other.tif"))
    p.on_terrain("p3", _info("b", "other.tif"))  # asked every second: flagged once
    (ev,) = p.take_events()
    assert isinstance(ev, ConflictEvent) and ev.planner == "p1" and ev.other == "p3"
    assert "other.tif" in ev.reason and "ridge.tif" in ev.reason and "m1" in ev.reason
    p.on_terrain("p3", _info("c"))  # and again when it changes terrain
    assert len(p.take_events()) == 1


def test_a_peer_on_flat_ground_conflicts_with_a_planner_over_terrain_and_both_flat_do_not() -> None:
    p, _ = _peers(_info("a"))
    p.on_terrain("p2", None)
    (ev,) = p.take_events()
    assert "no terrain" in ev.reason
    flat, _ = _peers(None)
    flat.on_terrain("p2", None)
    assert flat.take_events() == []
