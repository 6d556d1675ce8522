"""Two units each cut to nothing by the other, and who stopped whom (``deadlocks.Facing``, issue 33).

``Facing`` keeps, from ``keep_apart.cut``'s stopped pairs, how long two units have each stopped
the other (``dispersion`` makes such a pair one deadlock once it has held ``deadlock_s``, whatever
the two are doing: the gaps crowd's seed 9 finds one, ``u0140`` backing off into ``u0141``'s disc,
``u0141`` going north into its own) and which units stopped each unit in the last ``apply`` (a unit
found stuck is stuck against the one at rest among them, ``test_dispersion_stuck_against``).
"""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.world import deadlocks

pytestmark = pytest.mark.unit


def test_a_pair_each_stopping_the_other_is_timed_from_when_it_began_and_afresh_once_it_parts():
    facing = deadlocks.Facing()
    assert facing.pairs([("a", "b")], 0.0) == []  # one way only: no pair
    assert facing.pairs([("a", "b"), ("b", "a")], 1.0) == [("a", "b", 0.0)]
    assert facing.pairs([("b", "a"), ("a", "b"), ("a", "c")], 7.0) == [("a", "b", 6.0)]
    assert facing.pairs([("a", "c")], 8.0) == []  # parted
    assert facing.pairs([("a", "b"), ("b", "a")], 9.0) == [("a", "b", 0.0)]  # met again: afresh


def test_who_stopped_each_unit_is_the_last_applys_and_nothing_once_none_is_stopped():
    facing = deadlocks.Facing()
    facing.pairs([("a", "b"), ("a", "c"), ("d", "a")], 0.0)
    assert sorted(facing.stopping("a")) == ["b", "c"] and facing.stopping("d") == ["a"]
    assert facing.stopping("b") == []
    facing.pairs([], 1.0)
    assert facing.stopping("a") == []


def test_the_event_of_two_stopping_each_other_says_so_and_who_gives_way():
    e = deadlocks.event(
        "u0141", "u0140", np.array([1.0, 2.0]), 6.0, 6.0, False, None, facing=True, rounds=False
    )
    assert e.unit == "u0141" and e.other == "u0140" and e.held_s == 6.0
    assert (
        e.reason
        == "u0141 and u0140, each cut to nothing by the other for 6 s: u0141 gives way for at most 6 s"
    )
    both_round = deadlocks.event("u3", "u2", np.zeros(2), 0.0, 6.0, False, None, facing=True, rounds=True)
    assert "each going round a unit at rest, stop each other" in both_round.reason
