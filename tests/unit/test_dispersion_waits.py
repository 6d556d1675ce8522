"""A unit that gave way to one going round a unit at rest waits for that round (issue 33, `h-deadlock8`).

The gaps crowd's seed 2 (42 s on main, the one seed over 30 s): manned ``u0150`` went round ``u0149``
(arrived) through the place of ``u0108``, each cut to nothing by the other.  Found after ``deadlock_s``
(6 s of a 24 s round gone), ``u0108`` gave way; its back-off over, under its grace it drove straight back
into the round, still cut to 0-5 m a tick by the crowd, was found stuck against it and backed off again.
Now a round cut to nothing is found at once (it is a resolution failing), and the unit that gave way
waits for the round (yields to the unit going round, holding still) until that one's way is past it,
it has drawn away, or its round ends.

Scripted as `test_dispersion_chain`'s round scene: ``u0002`` goes round ``u0000`` (at rest on its goal)
into ``u0001``, a vehicle that reports the same position every second.
"""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.wire import DeadlockEvent, UnitKind
from pfp_service.world import deadlocks
from tests.unit.test_dispersion_chain import _run

pytestmark = pytest.mark.unit

_STARTS = [(0.0, 0.0), (60.0, -70.0), (2.0, -56.0)]
_GOALS = [(0.0, 0.0), (-600.0, -70.0), (0.0, 600.0)]


def _scene() -> tuple[list[tuple[float, DeadlockEvent]], list]:
    found, said, _ = _run(40, _STARTS, _GOALS, [UnitKind.UNMANNED] * 3, stalled=1, late={1: 3.0})
    return found, said


def test_a_round_cut_to_nothing_is_a_deadlock_at_once():
    """On main (``9a83ffe``) ``u0001`` gives way at 14 s, 6 s after the two first stopped each other."""
    found, _ = _scene()
    reasons = [e.reason for _, e in found]
    assert found[0][1].unit == "u0002" and found[0][1].other == "u0000", reasons  # the round, at 6 s
    t, lock = found[1]
    assert (lock.unit, lock.other) == ("u0001", "u0002"), reasons
    assert "u0002 going round a unit at rest" in lock.reason
    assert t < found[0][0] + 6.0  # within deadlock_s of the round's start: not a quarter of it gone


def test_a_unit_that_gave_way_waits_for_the_round_and_gives_way_once():
    """On main ``u0001`` backs off at 14 s, drives back into the round under its grace at 20 s and backs off
    again at 26 s: two back-offs within one round."""
    found, said = _scene()
    t_round = found[0][0]
    end = t_round + deadlocks.ROUND_BACKOFFS * 6.0  # the round's longest (backoff_s 6 s)
    gave_way = [t for t, e in found if e.unit == "u0001" and t_round <= t < end]
    assert len(gave_way) == 1, [e.reason for _, e in found]
    after = [(t, d) for t, d in said if d.unit == "u0001" and gave_way[0] + 6.0 <= t < end]
    assert after
    assert all(d.reason and d.reason.startswith("yielding to u0002") for _, d in after), after[0]


def test_the_event_names_the_unit_going_round():
    lock = deadlocks.event("u1", "u2", np.zeros(2), 0.0, 6.0, False, None, facing=True, rounding="u2")
    assert lock.reason == (
        "u1 and u2, each cut to nothing by the other, u2 going round a unit at rest: u1 gives way"
        " for at most 6 s"
    )
