"""A pushed descent with no clear side keeps to its right (issue 33, the gaps crowd's seed 12).

A pushed descent that would turn back goes square across the push on the side it was going
(``core.batch._pushed``).  Where the push runs within ``SIDE_CLEAR`` (15 degrees) of the descent's
line, that side is the sign of a cross product near 0: it flipped with each 5 m step, and the unit
stepped across and back at every report while the units round it waited for it (seed 12's ``u0110``
75 m from ``u0131``, which held 6 s for it and backed off from it 40 m off its own goal: 41 s to
cleared).  There it now keeps to the right of its descent, as vessels meeting head on each alter
to starboard; outside that band, and exactly head on, as before.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core.batch import SIDE_CLEAR, _pushed

pytestmark = pytest.mark.unit


def _moves(grad: tuple[float, float], push: tuple[float, float]) -> np.ndarray:
    """Where a unit with field gradient ``grad`` (it descends along ``-grad``) and ``push`` goes, a unit vector."""
    out = _pushed(np.array([grad]), np.array([[math.hypot(*grad)]]), np.array([push]))
    way = -out[0]
    return way / np.hypot(*way)


@pytest.mark.parametrize("off_deg", [-14.0, -5.0, -0.5, 0.5, 5.0, 14.0])
def test_a_push_nearly_straight_back_turns_the_descent_to_its_right_whichever_side_it_leans(off_deg):
    """Descending north (gradient south), pushed back from a neighbour within 15 degrees of straight
    ahead, on either side: always east, square to the push (before: east or west by the side)."""
    a = math.radians(off_deg)
    push = (2.0 * math.sin(a), 2.0 * math.cos(a))  # towards the neighbour ahead, in gradient terms: back
    way = _moves((0.0, -1.0), push)
    assert way[0] > 0.9, f"{off_deg} degrees off: {way}"
    assert float(way @ np.array(push)) == pytest.approx(0.0, abs=1e-12)


def test_a_push_clearly_to_one_side_and_one_straight_back_are_as_before():
    """20 degrees off (outside ``SIDE_CLEAR``): across on the descent's side, away from the neighbour;
    exactly head on: no side at all, the sum stands (the deadlock finds the pair)."""
    assert math.isclose(SIDE_CLEAR, math.sin(math.radians(15.0)))
    for off_deg, side in ((20.0, -1.0), (-20.0, 1.0)):
        a = math.radians(off_deg)
        way = _moves((0.0, -1.0), (2.0 * math.sin(a), 2.0 * math.cos(a)))
        assert side * way[0] > 0.9, f"{off_deg} degrees off: {way}"
    head_on = _pushed(np.array([[0.0, -1.0]]), np.ones((1, 1)), np.array([[0.0, 2.0]]))
    assert head_on[0] == pytest.approx([0.0, 1.0])
