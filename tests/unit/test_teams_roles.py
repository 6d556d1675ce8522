"""The roles' verdicts on one step (``world.teams``): lead, follow and the controller link, as pure functions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pfp_service.terrain.viewshed import lowest_visible_height
from pfp_service.world import teams as roles

pytestmark = pytest.mark.unit

ROUTE = [(0.0, 0.0), (100.0, 0.0), (100.0, 200.0)]


def test_project_and_point_at_walk_a_polyline() -> None:
    assert roles.project((50.0, 7.0), ROUTE) == pytest.approx((50.0, 7.0))
    assert roles.project((110.0, 150.0), ROUTE) == pytest.approx((250.0, 10.0))
    assert roles.point_at(ROUTE, 150.0) == pytest.approx((100.0, 50.0))
    assert roles.point_at(ROUTE, 1e6) == (100.0, 200.0)
    assert roles.project((3.0, 4.0), [(0.0, 0.0)]) == (0.0, 5.0)
    assert roles.project((3.0, 4.0), []) == (0.0, math.inf)


def test_lead_makes_for_its_place_standoff_ahead_along_the_main_route() -> None:
    v = roles.lead((20.0, 0.0), ROUTE, 150.0, "m1")
    assert v.kind == "to" and v.to == pytest.approx((100.0, 50.0))  # round the bend, not across it
    assert "leading m1 by 150 m" in v.reason


def test_lead_waits_when_the_main_element_falls_behind_and_only_then() -> None:
    v = roles.lead((100.0, 20.0), ROUTE, 100.0, "m1")  # 120 m along: past its place, never back
    assert v.kind == "hold" and v.reason == "at its standoff 100 m ahead of m1"
    v = roles.lead((100.0, 80.0), ROUTE, 100.0, "m1")  # 180 m along: more than 125 m
    assert v.kind == "hold" and v.reason == "waiting for m1: 180 m ahead along its route, standoff 100 m"
    assert roles.lead((100.0, 50.0), ROUTE, 150.0, "m1").kind == "hold"  # at its place


def test_follow_goes_inside_the_corridor_and_is_cut_short_where_the_step_leaves_it() -> None:
    track = [(0.0, 0.0), (100.0, 0.0)]
    assert roles.follow((10.0, 0.0), (30.0, 2.0), track, 10.0, "r1", "") == roles.GO
    v = roles.follow((10.0, 0.0), (30.0, 20.0), track, 10.0, "r1", "")  # leaves the 5 m half-width at y=5
    assert v.kind == "to" and v.to is not None and v.to[1] <= 5.0 and v.to[0] > 12.0
    assert "kept to the corridor r1 cleared" in v.reason


def test_follow_takes_the_track_when_its_step_leaves_the_corridor_at_once() -> None:
    track = [(0.0, 0.0), (100.0, 0.0)]
    v = roles.follow((10.0, 4.9), (10.0, 30.0), track, 10.0, "r1", "")
    assert v.kind == "to" and v.to == pytest.approx((35.1, 0.0), abs=0.5)  # along, as far as it asked
    v = roles.follow((10.0, 40.0), (10.0, 60.0), track, 10.0, "r1", "")  # outside: back in first
    assert v.kind == "to" and v.to == pytest.approx((10.0, 0.0)) and "back into the corridor" in v.reason


def test_follow_holds_at_the_end_of_the_cleared_ground_and_when_the_lead_is_lost() -> None:
    track = [(0.0, 0.0), (100.0, 0.0)]
    v = roles.follow((100.0, 0.0), (130.0, 0.0), track, 10.0, "r1", "")  # into the corridor's end cap
    assert v.kind == "to" and v.to == pytest.approx((104.9, 0.0))  # 2 % of the half-width inside its edge
    v = roles.follow((104.9, 0.0), (130.0, 0.0), track, 10.0, "r1", "")
    assert v.kind == "hold" and v.reason == "at the end of the ground r1 has cleared"
    v = roles.follow((10.0, 0.0), (30.0, 0.0), track, 10.0, "r1", "is lost (no report for a while)")
    assert v.kind == "hold" and v.reason == "holding: lead r1 is lost (no report for a while)"
    assert roles.follow((0.0, 0.0), (1.0, 0.0), [], 10.0, "r1", "").kind == "hold"


@given(
    at=st.tuples(st.floats(-50, 150), st.floats(-30, 30)),
    to=st.tuples(st.floats(-200, 300), st.floats(-200, 200)),
)
def test_a_follower_inside_the_corridor_is_never_sent_out_of_it(
    at: tuple[float, float], to: tuple[float, float]
) -> None:
    track = [(0.0, 0.0), (60.0, 0.0), (60.0, 80.0)]
    if roles.project(at, track)[1] > 5.0:
        return
    v = roles.follow(at, to, track, 10.0, "r1", "")
    end = to if v.kind == "go" else (v.to or at)
    for f in np.linspace(0.0, 1.0, 41):  # the whole step, not its end only
        p = (at[0] + (end[0] - at[0]) * f, at[1] + (end[1] - at[1]) * f)
        assert roles.project(p, track)[1] <= 5.0 + 0.3, (v, p)


def test_link_keeps_the_robot_within_radio_range() -> None:
    assert roles.link((0.0, 0.0), (50.0, 0.0), (0.0, 0.0), 100.0, "m1", "") == roles.GO
    v = roles.link((90.0, 0.0), (130.0, 0.0), (0.0, 0.0), 100.0, "m1", "")
    assert v.kind == "to" and v.to is not None and 90.0 < v.to[0] <= 100.0
    assert "the step would break the link to m1 (130 m from m1, radio range 100 m)" in v.reason
    v = roles.link((99.9, 0.0), (130.0, 0.0), (0.0, 0.0), 100.0, "m1", "")
    assert v.kind == "hold"


def test_link_lost_turns_back_and_a_stopped_controller_holds_the_robot() -> None:
    v = roles.link((150.0, 0.0), (160.0, 0.0), (0.0, 0.0), 100.0, "m1", "")
    assert v.kind == "to" and v.to == (0.0, 0.0)
    assert v.reason == "lost link (150 m from m1, radio range 100 m): turning back"
    v = roles.link((10.0, 0.0), (20.0, 0.0), (0.0, 0.0), 100.0, "m1", "has stopped")
    assert v.kind == "hold" and v.reason == "lost link: controller m1 has stopped"


def _ridge_sight() -> roles.Sight:
    """Line of sight from the controller's cell over a 30 m ridge at x = 50 m, by the project's viewshed (1 m cells)."""
    z = np.zeros((41, 121))
    z[:, 50] = 30.0
    ctl = (20, 10)  # row = y + 20, col = x
    lowest = lowest_visible_height(z, ctl, 2.0, 1e9, 1.0)

    def sight(c: tuple[float, float], p: tuple[float, float], clearance_m: float = 0.0) -> bool:
        assert (round(c[1]) + 20, round(c[0])) == ctl
        r, col = round(p[1]) + 20, round(p[0])
        return bool(lowest[r, col] <= 2.0 - clearance_m)

    return sight


def test_link_over_terrain_stops_short_of_the_ridge_shadow() -> None:
    sight = _ridge_sight()
    assert sight((10.0, 0.0), (45.0, 0.0)) and not sight((10.0, 0.0), (70.0, 0.0))
    v = roles.link((30.0, 0.0), (90.0, 0.0), (10.0, 0.0), 500.0, "m1", "", sight)
    assert v.kind == "to" and v.to is not None and 30.0 < v.to[0] <= 51.0
    assert "out of m1's line of sight" in v.reason
    v = roles.link((80.0, 0.0), (90.0, 0.0), (10.0, 0.0), 500.0, "m1", "", sight)
    assert v.kind == "to" and v.to == (10.0, 0.0) and "out of m1's line of sight" in v.reason


def test_lead_goes_its_own_way_once_the_main_element_s_route_left_is_within_its_standoff() -> None:
    assert roles.lead((20.0, 0.0), [(0.0, 0.0), (60.0, 0.0)], 100.0, "m1") == roles.GO


_coord = st.floats(-500.0, 500.0, allow_nan=False)


@given(
    st.lists(
        st.tuples(
            st.tuples(_coord, _coord),
            st.lists(st.tuples(_coord, _coord), min_size=0, max_size=12),
            st.floats(0.0, 400.0, allow_nan=False),
        ),
        min_size=1,
        max_size=8,
    )
)
def test_the_leads_judged_in_one_call_are_each_lead_judged_on_a_polyline_of_its_route(asks) -> None:
    """``leads`` (one compiled call over every route) says what a ``Polyline`` of each route says."""
    got = roles.leads([(at, route, standoff, f"m{k}") for k, (at, route, standoff) in enumerate(asks)])
    for k, ((at, route, standoff), verdict) in enumerate(zip(asks, got)):
        if not route:
            assert verdict.kind == "hold" and "no route" in verdict.reason
            continue
        line = roles.Polyline(route)
        if line.length <= standoff:
            assert verdict == roles.GO
            continue
        s, place = line.project(at)[0], line.point_at(standoff)
        if verdict.kind == "to":
            assert verdict.to == place and s < standoff - 1.0, (verdict, s, place)  # the very numbers
        else:
            assert verdict.kind == "hold" and f"m{k}" in verdict.reason
            assert s >= standoff - 1.0 or math.dist(at, place) < 1.0
            assert ("waiting for" in verdict.reason) == (s > standoff * (1.0 + roles.STANDOFF_TOLERANCE))
