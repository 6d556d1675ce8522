"""The warm-up loads the terrain's kernels only for a planner with terrain (and for every kernel when asked for none
in particular: a fresh clone's tests, a worker of a planner with terrain)."""

from __future__ import annotations

import pytest

from pfp_service.node import previews, warmup
from pfp_service.world.events import WorldSettings

pytestmark = pytest.mark.unit


@pytest.fixture
def swept(monkeypatch):
    calls: list[object] = []
    monkeypatch.setattr(warmup, "_terrain", calls.append)
    return calls


def test_a_planner_without_terrain_warms_no_terrain_kernel(swept):
    previews.warm_up(WorldSettings())
    assert swept == []


def test_every_kernel_when_no_settings_are_named(swept):
    previews.warm_up(None)
    assert len(swept) == 1


def test_a_worker_warms_as_its_planner_said(swept, monkeypatch):
    monkeypatch.setattr(previews, "WORKERS_WARM_TERRAIN", [False])
    previews._warm_worker()
    assert swept == []
    monkeypatch.setattr(previews, "WORKERS_WARM_TERRAIN", [True])
    previews._warm_worker()
    assert len(swept) == 1
