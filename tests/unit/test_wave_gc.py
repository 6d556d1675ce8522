"""The collector held off round ``World.apply`` by its driver (``gcpause``, as the node's loop does): none runs
inside, it runs once after, and its state is kept.  The world itself imports no collector."""

from __future__ import annotations

import gc
import types
import weakref

import pytest

from pfp_service.core import PlannerParams
from pfp_service.node import gcpause
from pfp_service.wire import Goal, ThreatUpdate, UnitState
from pfp_service.world.wave import WAVE_PER_TICK
from pfp_service.world.world import GoalSet, StateReported, ThreatPut, World, WorldSettings

pytestmark = pytest.mark.unit

FIRST_SHARE = min(80, WAVE_PER_TICK)  # the wave's directions in its first apply (``world.wave``)


@pytest.fixture
def collections():
    """The collections run (their generations) while the test runs, on a collector eager to run."""
    seen: list[int] = []

    def watch(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            seen.append(info["generation"])

    threshold, enabled = gc.get_threshold(), gc.isenabled()
    gc.enable()
    gc.set_threshold(50, 10, 10)  # a wave's apply makes thousands of containers: it would collect often
    gc.callbacks.append(watch)
    try:
        yield seen
    finally:
        gc.callbacks.remove(watch)
        gc.set_threshold(*threshold)
        (gc.enable if enabled else gc.disable)()


def _wave(n: int = 80) -> tuple[World, ThreatPut]:
    w = World(WorldSettings(planner=PlannerParams(escape="auto"), deliberation="deferred"))
    ids = [f"u{i:03d}" for i in range(n)]
    w.apply([StateReported(u, UnitState(position=(0.0, float(i)), seq=1)) for i, u in enumerate(ids)], 0.0)
    w.apply([GoalSet(u, Goal(position=(60.0, float(i)))) for i, u in enumerate(ids)], 0.0)
    t = ThreatUpdate(position=(20.0, 40.0), facing_deg=270.0, sigma_range=4.0, sigma_lateral=3.0, skew=2.0)
    return w, ThreatPut("c", t)


def test_no_collection_runs_inside_apply_and_one_runs_at_the_first_allocation_after(collections):
    w, put = _wave()
    collections.clear()
    with gcpause.paused():
        out = w.apply([put], 1.0)
    assert len(out.directions) == FIRST_SHARE
    assert collections == [] and gc.isenabled()
    assert gc.get_count()[0] > 50  # what apply made is counted, and owed to the collector
    types.SimpleNamespace()  # an allocation the collector counts
    assert collections, "the collection held off did not run after apply"
    assert gc.get_count()[0] < 50


def test_a_collector_already_off_stays_off(collections):
    w, put = _wave(8)
    gc.disable()
    with gcpause.paused():
        w.apply([put], 1.0)
    assert not gc.isenabled()


def test_paused_nests_and_restores_the_collector_through_an_exception(collections):
    with pytest.raises(RuntimeError), gcpause.paused():
        assert not gc.isenabled()
        with gcpause.paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # the inner one found it off: left off
        raise RuntimeError("boom")
    assert gc.isenabled()


def test_garbage_made_inside_is_collected_after(collections):
    class Cycle:
        def __init__(self) -> None:
            self.me = self

    with gcpause.paused():
        refs = [weakref.ref(Cycle()) for _ in range(500)]  # unreachable cycles: only the collector frees them
        assert all(r() is not None for r in refs)  # none collected inside
    types.SimpleNamespace()
    assert all(r() is None for r in refs)
