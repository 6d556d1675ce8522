"""The world's limits (world/limits.py): rejections paced per kind of key, faults logged once a minute per key."""

from __future__ import annotations

import pytest

from pfp_service.wire import keys
from pfp_service.world.limits import ANY_KEY, FAULT_KEYS_MAX, FAULT_LOG_S, REJECTS_PER_S, Limits

pytestmark = pytest.mark.unit


def test_rejections_go_out_at_most_five_a_second_per_kind_and_the_held_are_counted_in_the_next():
    lim = Limits()
    key = keys.KeyKind.UNIT_STATE  # the kind the caller knows: no key is parsed to learn it
    said = [lim.reject(key, 0.0) for _ in range(REJECTS_PER_S + 3)]
    assert said == [0] * REJECTS_PER_S + [None] * 3
    assert lim.reject(keys.KeyKind.THREAT, 0.1) == 0  # another kind of key has its own window
    assert lim.reject(key, 1.0) == 3  # a new second: the three held are said with the first
    assert lim.reject(key, 1.1) == 0
    assert lim.rejected == REJECTS_PER_S + 3 + 3


def test_a_key_outside_the_layout_is_paced_as_unknown():
    lim = Limits()
    assert [lim.reject(None, 0.0) for _ in range(REJECTS_PER_S)] == [0] * REJECTS_PER_S
    assert lim.reject(None, 0.0) is None
    assert lim.reject(keys.KeyKind.UNIT_GOAL, 0.0) == 0  # a kind's own window, apart from the unknown


def test_a_fault_is_logged_once_a_minute_per_key_with_the_count_held_since():
    lim = Limits()
    assert lim.fault("k1", 0.0) == ("k1", 0)
    assert lim.fault("k1", 1.0) is None and lim.fault("k1", 59.0) is None
    assert lim.fault("k2", 2.0) == ("k2", 0)  # another key: its own window
    assert lim.fault("k1", FAULT_LOG_S) == ("k1", 2)
    assert lim.faults == 5


def test_the_fault_windows_are_bounded_and_the_rest_share_one_line():
    lim = Limits()
    for i in range(FAULT_KEYS_MAX):
        assert lim.fault(f"k{i}", 0.0) == (f"k{i}", 0)
    assert lim.fault("one-too-many", 1.0) == (ANY_KEY, 0)
    assert lim.fault("and-another", 2.0) is None
    # once the old windows have passed, a new key has a window of its own again
    assert lim.fault("late", FAULT_LOG_S + 1.0) == ("late", 0)


def test_counts_name_the_figures_of_the_status_reply():
    lim = Limits()
    lim.overload += 2
    lim.reject(None, 0.0)
    lim.fault("x", 0.0)
    assert lim.counts() == {"overload": 2, "rejected": 1, "faults": 1}


def test_the_node_shed_and_the_world_refused_are_one_overload_count():
    from pfp_service.wire import Goal
    from pfp_service.world.world import GoalSet, Tick, World, WorldSettings

    w = World(WorldSettings(max_units=1))
    w.apply([GoalSet("a", Goal(position=(1.0, 1.0))), GoalSet("b", Goal(position=(1.0, 1.0)))], 0.0)
    assert w.counts()["overload"] == 1  # b: past max_units
    w.apply([Tick(1.0, shed=7)], 1.0)  # the node refused 7 at its queues since its last tick
    assert w.counts()["overload"] == 8
    w.apply([Tick(2.0)], 2.0)
    assert w.counts()["overload"] == 8
