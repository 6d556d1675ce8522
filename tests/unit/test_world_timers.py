"""The world's timer heap (world/timers.py): due in time order, stable for ties, set while draining."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pfp_service.world.timers import Timers

pytestmark = pytest.mark.unit


def test_only_what_is_due_comes_out_in_time_order():
    t = Timers()
    t.set(3.0, "forget", "c")
    t.set(1.0, "silence", "a")
    t.set(2.0, "expire", "b")
    assert list(t.due(2.0)) == [("silence", "a"), ("expire", "b")]
    assert len(t) == 1
    assert list(t.due(2.5)) == []
    assert list(t.due(3.0)) == [("forget", "c")] and not t


def test_timers_due_at_the_same_time_come_in_the_order_set():
    t = Timers()
    for i in range(5):
        t.set(1.0, "push", f"u{i}")
    assert [ident for _, ident in t.due(1.0)] == [f"u{i}" for i in range(5)]


def test_a_timer_set_while_draining_comes_out_in_the_same_drain_if_it_is_due():
    t = Timers()
    t.set(1.0, "silence", "a")
    seen = []
    for kind, ident in t.due(5.0):
        seen.append((kind, ident))
        if ident == "a":  # looked again: due later, but still by 5.0
            t.set(4.0, "silence", "a2")
            t.set(9.0, "silence", "late")
    assert seen == [("silence", "a"), ("silence", "a2")] and len(t) == 1


@given(st.lists(st.floats(0, 100, allow_nan=False), max_size=50), st.floats(0, 100, allow_nan=False))
def test_due_is_exactly_the_timers_at_or_before_now(whens, now):
    t = Timers()
    for i, w in enumerate(whens):
        t.set(w, "k", str(i))
    out = [int(ident) for _, ident in t.due(now)]
    assert sorted(out) == [i for i, w in enumerate(whens) if w <= now]
    assert [whens[i] for i in out] == sorted(whens[i] for i in out)
    assert len(t) == sum(w > now for w in whens)
