"""The warm-up leaves nothing of its throwaway worlds behind, and a planner warmed once is not warmed again."""

from __future__ import annotations

import pytest

from pfp_service.core.routes import ROUTES
from pfp_service.node import previews
from pfp_service.world.events import WorldSettings

pytestmark = pytest.mark.unit


def test_the_warm_up_s_route_grids_are_not_kept():
    searches = ROUTES.stats().searches
    previews.warm_up(WorldSettings())
    stats = ROUTES.stats()
    assert stats.searches > searches  # it searched (the trapped pair's shared grid) ...
    assert stats.entries == 0 and stats.nodes == 0  # ... and kept none of it


def test_warm_once_warms_a_planner_once(monkeypatch):
    wide: list[object] = []
    monkeypatch.setattr(previews, "warm_wide", lambda base, terrain: wide.append(base))
    monkeypatch.setattr(previews, "_WARMED", set())
    first = WorldSettings(lookahead=4)
    previews.warm_once(first)
    previews.warm_once(WorldSettings(lookahead=4, bounds=((0.0, 0.0), (1.0, 1.0))))  # the same planner
    assert len(wide) == 1
    previews.warm_once(WorldSettings(lookahead=6))  # another planner's parameters: warmed for them
    assert len(wide) == 2


def test_the_warm_up_s_crowd_searches_a_tight_grid_and_leaves_the_cache_s_room_as_it_was(monkeypatch):
    from pfp_service.core import routes

    built: list[int] = []
    build = routes.RouteCache._build

    def spy(self, ask, slot, shared):  # type: ignore[no-untyped-def]
        entry = build(self, ask, slot, shared)
        built.append(len(entry.grid.nodes))
        return entry

    monkeypatch.setattr(routes.RouteCache, "_build", spy)
    room = ROUTES.room
    previews.warm_up(WorldSettings(), terrain=False)
    assert built  # the trapped pair's shared goal was searched ...
    assert max(built) < 10_000  # ... on the asked box and cell (63,210 nodes with a shared goal's room)
    assert ROUTES.room == room == routes.ROOM
