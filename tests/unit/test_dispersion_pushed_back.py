"""A pushed descent never turns back: it goes square across the push (issue 33, the gaps crowd's seeds 17-24).

Within 4/3 separations of a neighbour the push outweighs the pull, so a unit whose goal lay beyond
a neighbour was pushed away from its goal (herded, while that neighbour came on) or stepped back
and forth where the two balanced, until a deadlock was found (seed 21: ``u0170`` herded from 119 to 205 m
off its goal, 86 s from the deadlock's start to cleared).  Now it goes round the neighbour (``core.batch._pushed``).
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import _crowd
from pfp_service.world.separations import DispersionSettings

pytestmark = pytest.mark.unit

ON = DispersionSettings(enabled=True)


def test_a_unit_whose_goal_lies_beyond_a_unit_at_rest_goes_round_it_never_back():
    """60 m north of a unit at rest on its own goal, its goal 300 m south, a little west: on main it was
    pushed back (3.5 m in one report), came no nearer its goal for 6 s, and a deadlock was found; now
    it never steps away from its goal, and no deadlock is found."""
    crowd = _crowd.Crowd(
        "a unit pushed back by one between it and its goal",
        starts=[(0.0, 0.0), (10.0, 60.0)],
        goals=[(0.0, 0.0), (-20.0, -300.0)],
        kinds=["manned", "unmanned"],
        threats={},
        limit_s=300.0,
    )
    locks: list = []
    tracks: list = []
    out = _crowd.simulate(crowd, ON, locks=locks, tracks=tracks)
    assert set(out.arrived_s) == {"u0000", "u0001"}
    goal = np.array(crowd.goals[1])
    to_goal = [float(np.hypot(*(t[1] - goal))) for t in tracks]
    assert max(b - a for a, b in zip(to_goal, to_goal[1:])) <= 0.0, "never away from its goal"
    assert not locks and out.closest_share >= 1.0


def test_the_push_turns_a_descent_across_not_back_and_leaves_head_on_and_forward_alone():
    from pfp_service.core.batch import _pushed

    grad = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])  # each descends south (against the gradient)
    norm = np.ones((3, 1))
    push = np.array([[0.3, -2.0], [0.0, -2.0], [0.5, 0.5]])  # back (a little east), straight back, forward
    out = _pushed(grad, norm, push)
    across = out[0] / np.hypot(*out[0])
    assert float(across @ push[0]) == pytest.approx(0.0, abs=1e-12)  # square to the push
    assert float(-out[0] @ -grad[0]) > 0.0 and float(np.hypot(*out[0])) == pytest.approx(1.0)  # still south
    assert out[1] == pytest.approx(grad[1] + push[1])  # head on: no side to go, the sum stands
    assert out[2] == pytest.approx(grad[2] + push[2])  # not turned back: the sum, as before
