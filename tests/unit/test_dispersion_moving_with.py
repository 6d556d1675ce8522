"""A unit beside a neighbour going its way moves with it (issue 33, the gaps crowd's seeds 9-16).

The cut (``keep_apart.cut``) treated every neighbour as standing for the tick: in a column packed
at the margin, a unit beside a slower neighbour going its way, within the margin, whose way leaned
into that neighbour's disc however slightly, held while the neighbour crept on (seed 11's ``u0128``
beside ``u0131``, 43 s from the deadlock's start to cleared).  Now a neighbour on its own way in the
tick, within 60 degrees of the unit's, moves in the cut too (``keep_apart.WITH``), and wherever it
stands the unit keeps its separation from it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.wire import Direction, DirectionStatus
from pfp_service.world import keep_apart

pytestmark = pytest.mark.unit

SEP = 50.0
STEP = 5.0


def _way(deg: float) -> tuple[float, float]:
    return (math.sin(math.radians(deg)), math.cos(math.radians(deg)))


def _direction(unit: str, deg: float, reach_m: float = STEP, status=DirectionStatus.EN_ROUTE) -> Direction:
    return Direction(unit=unit, status=status, vector=_way(deg), heading_deg=deg % 360.0, reach_m=reach_m)


def _cut(points: list[tuple[float, float]], dirs: list[Direction]) -> list[Direction]:
    """``dirs`` (the first ``len(dirs)`` units at ``points``, all moving) after the cut; the rest stand."""
    index = NeighbourIndex(np.array(points, dtype=float), np.full(len(points), SEP))
    keep_apart.cut(index, np.arange(len(dirs)), dirs, list(range(len(dirs))))
    return dirs


def _end(start: tuple[float, float], d: Direction) -> np.ndarray:
    return np.array(start) + np.array(d.vector) * min(STEP, d.reach_m or 0.0)


def test_a_unit_beside_a_neighbour_going_its_way_within_the_margin_moves_with_it():
    """Abreast at 52 m (within the margin's inner half), both north, the west one leaning 10 degrees into
    the other: on main it is cut to nothing and holds while the other goes on; now both go their 5 m,
    and after it, moved as told, they are still at their separation."""
    points = [(0.0, 0.0), (52.0, 0.0)]
    a, b = _cut(points, [_direction("a", 10.0), _direction("b", 0.0)])
    assert a.reach_m == pytest.approx(STEP) and b.reach_m == pytest.approx(STEP)
    assert float(np.hypot(*(_end(points[0], a) - _end(points[1], b)))) >= SEP
    assert float(np.hypot(*(_end(points[0], a) - np.array(points[1])))) >= SEP  # were it to stand after all


def test_two_units_converging_within_the_margin_close_to_about_their_separation():
    """54 m apart (within the margin), each 25 degrees off north towards the other: on main each is cut
    at the margin's inner disc from where the other stands (3.8 m); now each goes its 5 m (the other
    counted as moving no further than that cut leaves it), keeps its separation from where the other
    stands, and moved as told the two are within 1 % of their separation."""
    points = [(0.0, 0.0), (54.0, 0.0)]
    a, b = _cut(points, [_direction("a", 25.0), _direction("b", -25.0)])
    assert a.reach_m == pytest.approx(STEP) and b.reach_m == pytest.approx(STEP)
    assert float(np.hypot(*(_end(points[0], a) - np.array(points[1])))) >= SEP
    assert float(np.hypot(*(_end(points[0], a) - _end(points[1], b)))) >= 0.99 * SEP


def test_a_neighbour_that_does_not_move_is_kept_its_separation_and_one_crossing_or_yielding_the_margin():
    """The neighbour cut to nothing by a third unit standing just ahead of it: the unit keeps its
    separation from where it stands (so it goes on, 50.8 m past it).  Holding for another (yielding), or
    crossing the unit's way (over 60 degrees off it), it stands for the cut as on main: the unit holds."""
    points = [(0.0, 0.0), (52.0, 0.0), (52.0, 51.0)]
    a, b = _cut(points, [_direction("a", 10.0), _direction("b", 0.0)])
    assert b.reach_m == 0.0 and a.reach_m == pytest.approx(STEP)
    assert float(np.hypot(*(_end(points[0], a) - np.array(points[1])))) >= SEP
    yielding = _direction("b", 0.0, status=DirectionStatus.YIELDING)
    a, _ = _cut(points[:2], [_direction("a", 10.0), yielding])
    assert a.reach_m == 0.0
    a, _ = _cut(points[:2], [_direction("a", 10.0), _direction("b", 75.0)])
    assert a.reach_m == 0.0
