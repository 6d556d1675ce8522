"""The node's intake (world/intake.py): inputs in order, states latest-wins, bounded, sliced per tick."""

from __future__ import annotations

import pytest

from pfp_service.wire import UnitState
from pfp_service.world.events import Deliberated, GoalCancelled, Tick
from pfp_service.world.intake import Intake

pytestmark = pytest.mark.unit


def _s(x: float) -> UnitState:
    return UnitState(position=(x, 0.0), seq=int(x))


def test_states_are_latest_wins_and_a_unit_reporting_again_keeps_its_place():
    i = Intake(100, 10, 2)
    i.state("a", _s(1), 0.1)
    i.state("b", _s(2), 0.2)
    i.state("c", _s(3), 0.3)
    i.state("a", _s(4), 0.4)  # newer, in a's place: first in line
    got = i.take()
    assert list(got.states) == ["a", "b"] and got.states["a"] == (_s(4), 0.4) and got.more
    got = i.take()
    assert list(got.states) == ["c"] and not got.more and len(i) == 0


def test_inputs_keep_their_order_and_a_storm_is_spread_over_ticks():
    i = Intake(100, 3, 10)
    for k in range(7):
        assert i.put(GoalCancelled(f"u{k}"))
    slices = [i.take() for _ in range(3)]
    assert [[g.unit for g in s.inputs] for s in slices] == [["u0", "u1", "u2"], ["u3", "u4", "u5"], ["u6"]]  # type: ignore[union-attr]
    assert [s.more for s in slices] == [True, True, False]


def test_past_its_bound_an_input_is_refused_and_counted_but_never_a_deliberations_answer():
    i = Intake(2, 10, 10)
    assert i.put(Tick(0.0)) and i.put(Tick(1.0))
    assert not i.put(GoalCancelled("u"))
    assert i.put(Deliberated("u", (0, 0), None))  # its job would stand forever
    i.refused(3)  # shed at another queue (writes, queries)
    got = i.take()
    assert got.shed == 4 and len(got.inputs) == 3
    assert i.take().shed == 0  # said once


def test_a_class_named_by_a_replaced_state_is_kept_on_the_newest_that_names_none():
    from pfp_service.wire import GoalMobility

    wheeled, tracked = GoalMobility(kind="wheeled"), GoalMobility(kind="tracked")
    i = Intake(100, 10, 2)
    i.state("a", UnitState(position=(0.0, 0.0), seq=1, mobility=wheeled), 0.1)
    i.state("b", UnitState(position=(0.0, 0.0), seq=1, mobility=wheeled), 0.1)
    i.state("c", UnitState(position=(0.0, 0.0), seq=1, mobility=wheeled), 0.1)
    i.state("a", _s(2), 0.2)  # names none: a's class stays with it
    i.state("b", UnitState(position=(0.0, 0.0), seq=2, mobility=tracked), 0.2)  # names another: the newest's
    got = i.take()
    assert got.states["a"][0].mobility == wheeled and got.states["a"][0].seq == 2
    assert got.states["b"][0].mobility == tracked
    i.state("c", _s(3), 0.3)  # c still waits (2 units a tick): its class is kept for the next
    got = i.take()
    assert got.states["c"][0].mobility == wheeled and got.states["c"][0].seq == 3
    i.state("a", _s(4), 0.4)  # taken already: nothing left to carry
    assert i.take().states["a"][0].mobility is None
