"""A pushed descent with no clear side keeps the side it went last (issue 33, the gaps crowd's seeds 3-17).

Where a neighbour stands within a few degrees of straight between a unit and its goal, "square
across the push on the side it was going" (``core.batch._pushed``) was the sign of a cross product
near 0: each 5 m step flipped it, and the unit stepped to and fro while its neighbours waited (seed
12: 41 s from a deadlock's start to cleared).  Within ``SIDE_CLEAR`` of the push's line the unit now
keeps the side of its last direction (hysteresis); outside that band, the side is as before.
"""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.core.batch import _pushed

pytestmark = pytest.mark.unit


def _steps(hysteresis: bool, n: int = 8) -> list[float]:
    """Each step's east part: a unit at the origin, its goal 45 m north (0.5 m east), a neighbour at rest
    55 m north; the push (towards the neighbour in the gradient's terms) outweighs the goal's pull."""
    goal, other = np.array([0.5, 45.0]), np.array([0.0, 55.0])
    at, last, east = np.zeros(2), np.zeros((1, 2)), []
    for _ in range(n):
        grad = (at - goal) / np.hypot(*(at - goal))  # the field rises away from the goal
        push = 1.5 * (other - at) / np.hypot(*(other - at))
        total = _pushed(grad[None], np.ones((1, 1)), push[None], last if hysteresis else None)[0]
        way = -total / np.hypot(*total)
        at, last = at + 5.0 * way, way[None]
        east.append(float(way[0]))
    return east


def test_a_unit_with_its_neighbour_almost_straight_ahead_keeps_one_side():
    east = _steps(hysteresis=True)
    assert all(e > 0.5 for e in east), east  # one side, square across, every step
    flipped = _steps(hysteresis=False)  # the side from the cross product alone: to and fro
    assert all(a * b < 0.0 for a, b in zip(flipped, flipped[1:])), flipped


def test_a_clear_side_is_kept_whatever_the_last_direction():
    grad = np.array([[0.0, -1.0]])  # descends north
    push = np.array([[1.0, 2.0]])  # back, well east of the line: the side is west
    west = _pushed(grad, np.ones((1, 1)), push, np.array([[1.0, 0.0]]))  # it went east last
    assert west == pytest.approx(_pushed(grad, np.ones((1, 1)), push))
    assert float(-west[0, 0]) < 0.0


def test_no_last_direction_leaves_the_rule_as_it_was():
    grad = np.array([[0.0, -1.0]])
    push = np.array([[0.05, 2.0]])  # within the band: the cross product's side
    assert _pushed(grad, np.ones((1, 1)), push, np.zeros((1, 2))) == pytest.approx(
        _pushed(grad, np.ones((1, 1)), push)
    )
