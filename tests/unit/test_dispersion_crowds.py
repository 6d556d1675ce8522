"""Dispersion in crowds (issue 33): what the full ``pfp bench dispersion`` rows found, each in a small case.

Two units head on, on one line, are a deadlock (the manned one pushed the other back before it
for its whole route, and it never arrived); one deadlock found from both its units in one tick is
resolved once (both backed off, the second as escalation's, met again and locked again); the cut
stops a unit at a neighbour's disc; and two units going round units at rest, each cut to nothing by
the other, are one deadlock (towards each other in the one lane between them, they held each other
for good: seed 3 of the gaps crowd with a slide along the disc, tried and not kept). Jams (issue
33's seeds 1-8): a unit giving way keeps the unit it gives way to only its separation, a back-off
cut to nothing turns to a free way, a yielding unit in the way of the unit it yields to makes
room, and a unit on a neighbour's disc may lean into the margin, no nearer than its inner half.
The crowds are driven through the sans-I/O world in process (``benchmarks._crowd.simulate``)
and measured on the tracks.
"""

from __future__ import annotations

import dataclasses
import math

import msgspec
import numpy as np
import pytest

from benchmarks import _crowd
from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.wire import Direction, DirectionStatus
from pfp_service.world import keep_apart
from pfp_service.world.separations import DispersionSettings

pytestmark = pytest.mark.unit

ON = DispersionSettings(enabled=True)
SEP = 50.0  # the wheeled class's separation, every unit here
DISC = 1.1 * SEP  # the documented cut: no direction takes a unit within 1.1 separations of another


def _cut(points: list[tuple[float, float]], way: tuple[float, float], reach_m: float = 40.0) -> Direction:
    """The first unit's direction along ``way`` after the cut, the others standing at ``points[1:]``."""
    index = NeighbourIndex(np.array(points, dtype=float), np.full(len(points), SEP))
    heading = math.degrees(math.atan2(way[0], way[1])) % 360.0
    dirs = [
        Direction(unit="a", status=DirectionStatus.EN_ROUTE, vector=way, heading_deg=heading, reach_m=reach_m)
    ]
    keep_apart.cut(index, np.array([0]), dirs, [0])
    return dirs[0]


def test_two_units_going_round_units_at_rest_towards_each_other_are_one_deadlock_and_both_arrive():
    """Each cut to nothing by the other in the one lane, each resolving its own deadlock with a unit at
    rest: on main they went round, stopped each other, and went round again every 31 s, for good."""
    crowd = _crowd.lane()
    locks: list = []
    out = _crowd.simulate(crowd, ON, locks=locks)
    assert {"u0002", "u0003"} <= set(out.arrived_s), f"arrived: {sorted(out.arrived_s)}"
    between = [e for _, e in locks if {e.unit, e.other} == {"u0002", "u0003"}]
    assert len(between) == 1 and between[0].unit == "u0003", "one deadlock, the lower by id gives way"
    assert "u0003 and u0002, each going round a unit at rest, stop each other" in between[0].reason
    assert out.closest_share >= 0.9 and out.not_cleared == 0


def test_the_cut_stops_a_unit_at_its_neighbours_disc_and_only_there():
    d = _cut(
        [(0.0, 0.0), (0.0, 90.0)], (0.0, 1.0), reach_m=80.0
    )  # straight at a unit ahead: stops at its disc
    assert d.vector == (0.0, 1.0) and d.reach_m == pytest.approx(90.0 - DISC)
    d = _cut([(0.0, 0.0), (90.0, 0.0)], (0.0, 1.0))  # beside it, going past: untouched
    assert d.vector == (0.0, 1.0) and d.reach_m == 40.0


@pytest.mark.parametrize("gap_m", [60.0, 68.0])
def test_two_units_head_on_on_one_line_both_arrive_and_the_deadlock_clears_within_30_s(gap_m):
    crowd = _crowd.head_on(gap_m)
    locks: list = []
    tracks: list = []
    out = _crowd.simulate(crowd, ON, locks=locks, tracks=tracks)
    assert set(out.arrived_s) == set(crowd.ids()), f"arrived: {out.arrived_s}"
    assert locks and locks[0][1].unit == "u0001"  # the unmanned one gives way
    assert out.not_cleared == 0 and out.longest_clearing_s <= 30.0
    assert min(float(np.hypot(*(p[0] - p[1]))) for p in tracks) >= 0.9 * SEP


def test_a_deadlock_found_from_both_its_units_in_one_tick_is_resolved_once():
    """Each resolving it, both backed off (the second as escalation's): they met again, and locked again.

    On one line (``near_its_goal`` with ``u0001``'s start and goal moved onto x = 0, ``u0000``'s way):
    off it, a pushed descent goes round the unit ahead rather than back (``core.batch._pushed``), and
    no deadlock arises; head on, the sum stands, and the deadlock does.
    """
    crowd = dataclasses.replace(_crowd.near_its_goal(), starts=[(0.0, 0.0), (0.0, 56.0)])
    crowd = dataclasses.replace(crowd, goals=[(0.0, 600.0), (0.0, 10.0)])
    locks: list = []
    out = _crowd.simulate(crowd, ON, locks=locks)
    assert locks and all(t == locks[0][0] for t, _ in locks[:1]), "the case is a real one: a deadlock arises"
    first = [(e.unit, e.other) for t, e in locks if t == locks[0][0]]
    assert first == [("u0000", "u0001")], f"one resolution, the unmanned one's: {first}"
    assert set(out.arrived_s) == set(crowd.ids()) and out.not_cleared == 0 and out.longest_clearing_s <= 30.0


def test_a_unit_yielding_does_not_stop_with_its_disc_the_unit_it_yields_to():
    """Gaps crowd, seed 4 (81 s to clear on main): unmanned ``u0001`` yields to manned ``u0000`` 55 m west
    of it (their paths meet), holding still; ``u0000``'s way leans into ``u0001``'s disc of 1.1
    separations, and the cut held it there; ``u0001``'s back-off was cut by a unit at rest behind it.
    Each held the other for good: on main neither moving unit arrives in 400 s, a deadlock every 18 s."""
    crowd = _crowd.jam()
    records: list = []
    tracks: list = []
    out = _crowd.simulate(crowd, ON, record=records, tracks=tracks)
    first = [d for t, d in records if t == 0.0 and d.unit in ("u0000", "u0001")]
    assert [d.status for d in first] == [DirectionStatus.EN_ROUTE, DirectionStatus.YIELDING], first
    assert first[0].reach_m is not None and first[0].reach_m > 0.0, (
        "held by the disc of the unit yielding to it"
    )
    assert set(out.arrived_s) == set(crowd.ids()), f"arrived: {sorted(out.arrived_s)}"
    assert out.deadlocks == 0 and out.not_cleared == 0
    assert min(float(np.hypot(*(p[0] - p[1]))) for p in tracks) >= 0.9 * SEP


def _cut_from(points: list[tuple[float, float]], way: tuple[float, float], gives_way=None) -> float:
    """The first unit's reach along ``way`` after the cut, the others standing at ``points[1:]``."""
    index = NeighbourIndex(np.array(points, dtype=float), np.full(len(points), SEP))
    dirs = [Direction(unit="a", status=DirectionStatus.EN_ROUTE, vector=way, reach_m=40.0)]
    stopped = keep_apart.cut(index, np.array([0]), dirs, [0], gives_way)
    assert dirs[0].reach_m is not None and bool(stopped) == (dirs[0].reach_m <= 1e-6)
    return dirs[0].reach_m


def test_the_cut_keeps_a_unit_only_its_separation_from_a_unit_giving_way_to_it_and_the_margin_from_others():
    west = (-1.0, 0.0)  # straight at a unit 60 m west of it
    assert _cut_from([(0.0, 0.0), (-60.0, 0.0)], west) == pytest.approx(60.0 - DISC)
    assert _cut_from([(0.0, 0.0), (-60.0, 0.0)], west, np.array([-1, 0])) == pytest.approx(60.0 - SEP)
    assert _cut_from([(0.0, 0.0), (-60.0, 0.0)], west, np.array([1, -1])) == pytest.approx(60.0 - DISC)


def test_a_unit_on_a_neighbours_disc_may_lean_into_the_margin_but_no_nearer_than_its_inner_disc():
    """Gaps crowds, seeds 1-8 (the front rows of the middle gap's column, every unit parked on a
    neighbour's disc of 1.1 separations by the cut): a unit on that disc whose way leaned into it however
    slightly was cut to nothing, and stood while the neighbour stood; on main every way below leaning
    into the disc is cut to 0 m.  Now the margin's inner half is kept (``keep_apart.INSIDE``): at most
    0.05 separations of it are given up, so a step of 5 m leaves every pair at 0.95 separations."""
    inner = 1.05 * SEP  # keep_apart.INSIDE: the margin's inner half
    lean = (-0.1, math.sqrt(1.0 - 0.01))  # 5.5 m into the disc of a unit 55 m west: passes at 54.7 m
    assert _cut_from([(0.0, 0.0), (-DISC, 0.0)], lean) == pytest.approx(40.0)
    west = (-1.0, 0.0)  # straight at it: to the inner disc, or to its separation when it gives way
    assert _cut_from([(0.0, 0.0), (-DISC, 0.0)], west) == pytest.approx(DISC - inner)
    assert _cut_from([(0.0, 0.0), (-DISC, 0.0)], west, np.array([-1, 0])) == pytest.approx(DISC - SEP)
    steep = (-0.6, 0.8)  # into the inner disc: stops on it
    reach = _cut_from([(0.0, 0.0), (-DISC, 0.0)], steep)
    end = np.array(steep) * reach
    assert 0.0 < reach < 40.0 and float(np.hypot(*(end - (-DISC, 0.0)))) == pytest.approx(inner)
    assert _cut_from([(0.0, 0.0), (-51.0, 0.0)], west) == 0.0  # inside the inner disc: held, as before


def test_a_back_off_cut_to_nothing_turns_to_the_nearest_free_way_still_away_from_the_other():
    """Gaps crowd, seeds 3 and 4: a unit backing off into a neighbour's disc was cut to nothing for the
    whole back-off, and the deadlock it was to clear formed again as it ended."""
    # backing off south from the other (north), a unit 52 m due south of it (within the margin's inner
    # half, 1.05 separations) and one 55 m east of it (on its disc: it may lean 2.5 m into it)
    points = [(0.0, 0.0), (0.0, 60.0), (0.0, -52.0), (55.0, 0.0)]
    index = NeighbourIndex(np.array(points, dtype=float), np.full(len(points), SEP))
    away = np.array([0.0, -60.0])
    dirs = [Direction(unit="a", status=DirectionStatus.YIELDING, vector=(0.0, -1.0), reach_m=SEP)]
    assert keep_apart.cut(index, np.array([0]), dirs, [0]) and dirs[0].reach_m == 0.0  # the case
    # on the southern unit's disc every turn towards it is cut, and east is the other's: due west is free
    assert keep_apart.free_way(index, 0, (0.0, -1.0), away, SEP) == pytest.approx((-1.0, 0.0, SEP))
    points[2] = (0.0, -70.0)  # 15 m off its disc: 30 degrees west of south reaches 8.6 m, 60 the whole way
    index = NeighbourIndex(np.array(points, dtype=float), np.full(len(points), SEP))
    assert keep_apart.free_way(index, 0, (0.0, -1.0), away, SEP) == pytest.approx(
        (-math.sqrt(0.75), -0.5, SEP)
    )
    boxed = NeighbourIndex(
        np.array(points + [(-52.0, 0.0), (-37.0, -37.0), (37.0, -37.0)], dtype=float), np.full(7, SEP)
    )
    assert keep_apart.free_way(boxed, 0, (0.0, -1.0), away, SEP) is None  # every turn away from it is cut


def test_a_unit_making_room_goes_square_to_the_way_of_the_unit_it_yields_to_on_its_own_side():
    from pfp_service.world.deadlocks import aside_vector

    north = (0.0, 1.0)
    assert aside_vector(np.array([-5.0, 50.0]), north) == pytest.approx((-1.0, 0.0))  # ahead, to the west
    assert aside_vector(np.array([5.0, 50.0]), north) == pytest.approx((1.0, 0.0))
    assert aside_vector(np.array([0.0, 50.0]), north) == pytest.approx((-1.0, 0.0))  # dead ahead: its left
    assert aside_vector(np.array([0.0, 50.0]), (0.0, 0.0)) == (0.0, 0.0)


def test_a_unit_holding_still_in_the_way_of_the_unit_it_yields_to_makes_room_square_to_its_way():
    """Gaps crowd, seed 3 (39 s to clear with the separation alone against a unit giving way): ``u0111``
    yielded to ``u0108`` holding still right in its way, and ``u0108`` waited at its disc for 20 s."""
    from pfp_service.world.deadlocks import Hold

    # ``a`` (row 0) going north; ``b`` (row 1), at its separation north-west of it, yields to it, holding still
    points = np.array([(0.0, 0.0), (-20.0, 45.8)], dtype=float)
    index = NeighbourIndex(points, np.full(2, SEP))
    row = {"a": 0, "b": 1}
    yielding = "yielding to a (right of way by id): 50 m away, separation 50 m; goes when it has passed"
    dirs = [
        Direction(
            unit="a", status=DirectionStatus.EN_ROUTE, vector=(0.0, 1.0), heading_deg=0.0, reach_m=40.0
        ),
        Direction(unit="b", status=DirectionStatus.YIELDING, vector=(0.0, 0.0), reach_m=0.0, reason=yielding),
    ]
    holds = {"b": Hold("a", 0.0, 50.0)}
    gives_way = keep_apart.giving_way(index, row, holds, dirs, [0, 1])
    assert gives_way is not None and gives_way.tolist() == [-1, 0]
    stopped = keep_apart.cut(index, np.array([0]), dirs, [0], gives_way)
    assert stopped == [(0, 1)] and dirs[0].reach_m == 0.0  # the case: its disc stops the unit it yields to
    assert keep_apart.make_room(index, row, dirs, [0, 1], stopped, gives_way) == [1]
    b = dirs[1]
    assert b.status is DirectionStatus.YIELDING and b.vector == pytest.approx((-1.0, 0.0))  # west: its side
    assert b.reach_m is not None and b.reach_m > 0.0 and "making room" in b.reason
    # the unit it yields to going east, off its disc: not in its way, it holds still
    dirs[0] = msgspec.structs.replace(dirs[0], vector=(1.0, 0.0), reach_m=40.0)
    dirs[1] = msgspec.structs.replace(dirs[1], vector=(0.0, 0.0), reach_m=0.0, reason=yielding)
    stopped = keep_apart.cut(index, np.array([0]), dirs, [0], gives_way)
    assert not stopped and keep_apart.make_room(index, row, dirs, [0, 1], stopped, gives_way) == []


def test_a_back_off_goes_more_aside_than_away_still_drawing_away():
    """Gaps crowd, seeds 1 and 2 (42 and 38 s to clear at 45 degrees): a back-off gives ground its unit must
    win back before the deadlock counts as cleared; aside is what clears the line between the two."""
    from pfp_service.world.deadlocks import back_off_vector

    vx, vy = back_off_vector(np.array([0.0, -60.0]), (0.0, 0.0))  # the other unit 60 m north of it
    away = -vy  # the share of the back-off that is ground given
    assert 0.0 < away < math.cos(math.radians(60.0)) and vx > 0.0  # east: left as seen from the other
    assert math.hypot(vx, vy) == pytest.approx(1.0)
    assert back_off_vector(np.array([0.0, -60.0]), (0.0, 0.0)) == pytest.approx((2.0 / 5**0.5, -1.0 / 5**0.5))
