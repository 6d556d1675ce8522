"""Lost-link behaviour on analytic ground (issue 33): a robot never steps out of its link where holding keeps
it, its controller's own step counted; a robot out of link retraces its breadcrumbs to where the link held;
a robot held at a crest waits a bounded time for its controller to come up."""

from __future__ import annotations

import math

import pytest

from pfp_service.wire import Direction, DirectionStatus
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world import team_link
from pfp_service.world import teams as roles
from pfp_service.world.team_link import LINK_WAIT_S, Trails

pytestmark = pytest.mark.unit

Point = tuple[float, float]


def _spur_sight(a: Point, b: Point, clearance_m: float = 0.0) -> bool:
    """A ridge too high to see over along x = 50 m, from y = 0 north (a spur ending at the x axis)."""
    if (a[0] - 50.0) * (b[0] - 50.0) >= 0.0:
        return True  # both on one side (or on the ridge's line)
    y = a[1] + (b[1] - a[1]) * (50.0 - a[0]) / (b[0] - a[0])
    return y <= 0.0


def _ridge_sight(a: Point, b: Point, clearance_m: float = 0.0) -> bool:
    """A ridge too high to see over along x = 50 m, end to end."""
    return (a[0] - 50.0) * (b[0] - 50.0) >= 0.0


def _direction(unit: str, vector: Point, reach_m: float) -> Direction:
    return Direction(unit=unit, vector=vector, status=DirectionStatus.EN_ROUTE, reach_m=reach_m)


def test_a_robots_step_is_cut_where_its_controllers_own_step_would_lose_it_over_the_ridge() -> None:
    at, to, c, c_next = (60.0, -10.0), (100.0, -10.0), (0.0, -40.0), (0.0, 20.0)
    assert _spur_sight(c, to) and _spur_sight(c_next, at) and not _spur_sight(c_next, to)
    assert roles.link(at, to, c, 500.0, "m1", "", _spur_sight) == roles.GO  # judged where m1 is only
    v = roles.link(at, to, c, 500.0, "m1", "", _spur_sight, controller_next=c_next)
    assert v.kind == "to" and v.to is not None and 60.0 < v.to[0] <= 75.0, v  # the shadow starts at x = 75
    assert "out of link with where m1's own step takes it" in v.reason
    # already at the edge: it holds, where stepping on breaks the link the moment both have moved
    v = roles.link((75.0, -10.0), to, c, 500.0, "m1", "", _spur_sight, controller_next=c_next)
    assert v.kind == "hold"


def test_a_controllers_step_that_loses_the_robot_whatever_it_does_is_not_the_robots_to_hold_for() -> None:
    at, to, c = (40.0, 0.0), (45.0, 0.0), (30.0, 0.0)
    # m1 crosses the ridge: a hold keeps nothing, so the robot is judged where m1 is
    assert roles.link(at, to, c, 500.0, "m1", "", _ridge_sight, controller_next=(60.0, 0.0)) == roles.GO


def test_range_counts_the_controllers_step_too() -> None:
    v = roles.link((40.0, 0.0), (90.0, 0.0), (0.0, 0.0), 100.0, "m1", "", controller_next=(-50.0, 0.0))
    assert v.kind == "to" and v.to is not None and 40.0 < v.to[0] <= 50.0


def test_a_controller_keeps_where_its_robot_is_going_in_sight() -> None:
    robots = [("r1", (60.0, -10.0))]
    ahead = {"r1": (100.0, -10.0)}
    at, to = (0.0, -40.0), (0.0, 20.0)  # north: past y = 10 the spur hides where the robot is going
    assert roles.control(at, to, robots, 500.0, _spur_sight)[0] == roles.GO
    v, robot = roles.control(at, to, robots, 500.0, _spur_sight, ahead)
    assert v.kind == "to" and v.to is not None and robot == "r1"
    assert not _spur_sight(to, ahead["r1"]) and _spur_sight(v.to, ahead["r1"]) and 0.0 < v.to[1] <= 10.0


def test_a_robot_out_of_link_goes_back_along_its_breadcrumbs_not_straight_at_its_controller() -> None:
    back = [(40.0, 0.0), (60.0, 0.0), (70.0, 30.0)]  # linked at (40, 0); then on, over the ridge
    v = roles.link((80.0, 40.0), (90.0, 40.0), (10.0, 0.0), 500.0, "m1", "", _ridge_sight, back=back)
    assert v.kind == "to" and v.to == (70.0, 30.0)
    assert v.reason == "lost link (out of m1's line of sight): back along its track to where the link held"
    v = roles.link((80.0, 40.0), (90.0, 40.0), (10.0, 0.0), 500.0, "m1", "", _ridge_sight)
    assert v.kind == "to" and v.to == (10.0, 0.0) and v.reason.endswith(": turning back")  # no crumbs


def test_trails_keep_the_track_since_the_link_held_and_drop_each_crumb_reached() -> None:
    t = Trails()
    assert t.trail("r1", (0.0, 0.0), linked=False) == []  # never linked: nowhere to go back to
    assert t.trail("r1", (40.0, 0.0), linked=True) == []
    t.went_on("r1", (40.0, 0.0))  # on from where the link held: already its first crumb
    assert t.trail("r1", (60.0, 0.0), linked=False) == [(40.0, 0.0)]
    t.went_on("r1", (60.0, 0.0))  # on out of link (through a shadow): each place it went on from is a crumb
    assert t.trail("r1", (70.0, 30.0), linked=False) == [(40.0, 0.0), (60.0, 0.0)]
    assert t.trail("r1", (61.0, 1.0), linked=False) == [(40.0, 0.0)]  # back at (60, 0): reached
    assert t.trail("r1", (41.0, 0.0), linked=False) == []  # back where the link held, and still lost
    assert t.trail("r1", (42.0, 0.0), linked=True) == [] and t.crumbs["r1"] == [(42.0, 0.0)]


def test_a_robot_driven_by_its_verdicts_retraces_its_track_to_where_the_link_held() -> None:
    """The robot left its link at (40, 0) and went on round a bend; lost, it drives back along the bend."""
    team = TeamUpdate(controller="m1", robots=["r1"], radio_range_m=500.0, corridor_m=40.0)
    t = Trails()
    c = (10.0, 0.0)
    path = [(40.0, 0.0), (60.0, 0.0), (70.0, 20.0), (70.0, 40.0)]
    for k, p in enumerate(path):  # linked at the first only; it went on through the shadow
        assert t.trail("r1", p, linked=_ridge_sight(c, p)) == ([] if k == 0 else path[:k])
        t.went_on("r1", p)
    at, driven = path[-1], [path[-1]]
    for _ in range(20):
        v, _pull = team_link.robot_step(
            t, "r1", at, (at[0] + 5.0, at[1]), team, c, "", _ridge_sight, None, 0.0
        )
        if v.kind != "to" or v.to is None:
            break
        far = math.dist(at, v.to)
        run = min(15.0, far)  # 15 m a report, no further than the direction holds
        at = (at[0] + (v.to[0] - at[0]) / far * run, at[1] + (v.to[1] - at[1]) / far * run)
        driven.append(at)
        if _ridge_sight(c, at):
            break
    assert _ridge_sight(c, driven[-1]), driven
    for p in driven:  # every place on the way back lies on its own track, not the straight line to m1
        off = min(roles.project(p, [path[i], path[i + 1]])[1] for i in range(len(path) - 1))
        assert off < 1e-6, (p, driven)
    assert any(p[1] > 10.0 for p in driven[1:])  # round the bend: the straight way to m1 runs along y < 10


def test_a_robot_held_at_a_crest_beside_its_controller_waits_then_crosses() -> None:
    team = TeamUpdate(controller="m1", robots=["r1"], radio_range_m=500.0, corridor_m=40.0)
    t = Trails()
    at, to, c = (45.0, 0.0), (80.0, 0.0), (30.0, 0.0)  # m1 15 m behind it, the crest 5 m ahead
    v, pull = team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, 100.0)
    assert v.kind == "to" and v.to is not None and v.to[0] <= 50.0 and not pull  # up to the crest
    at = (50.0, 0.0)
    v, pull = team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, 105.0)
    assert v.kind == "hold" and pull  # it holds; m1 is told to close on it
    v, pull = team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, 105.0 + LINK_WAIT_S - 1)
    assert v.kind == "hold" and pull
    v, pull = team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, 105.0 + LINK_WAIT_S)
    assert v.kind == "to" and v.to == to
    assert v.reason.endswith(
        f"out of m1's sight over the crest beside it: it follows after {LINK_WAIT_S:,.0f} s"
    )
    far = (-100.0, 0.0)  # a controller 150 m back is not beside it: the robot holds for it to come up
    v, _ = team_link.robot_step(t, "r1", at, to, team, far, "", _ridge_sight, None, 105.0 + 10 * LINK_WAIT_S)
    assert v.kind == "hold"


def test_a_robot_whose_way_to_its_controller_leaves_its_sight_holds_a_while_then_goes_through() -> None:
    team = TeamUpdate(controller="m1", robots=["r1"], radio_range_m=500.0)
    t = Trails()

    def pit_sight(a: Point, b: Point, clearance_m: float = 0.0) -> bool:
        """A hollow 20 m round (50, -30) too deep to see out of, the ground round it level."""
        return math.dist(a, (50.0, -30.0)) > 20.0 and math.dist(b, (50.0, -30.0)) > 20.0

    at, c = (35.0, -15.0), (90.0, -70.0)  # m1 beyond the hollow: the straight way to it goes down into it
    v, pull = team_link.closing_on(t, "r1", at, c, team, pit_sight, 0.0)
    assert v.kind == "hold" and pull and "m1 closes on it" in v.reason
    v, pull = team_link.closing_on(t, "r1", at, c, team, pit_sight, LINK_WAIT_S - 1.0)
    assert v.kind == "hold" and pull
    v, pull = team_link.closing_on(t, "r1", at, c, team, pit_sight, LINK_WAIT_S)
    assert v.kind == "to" and v.to == c and pull and v.reason.endswith("through m1's shadow after 60 s")
    assert t.crumbs["r1"] == [at]  # where its link held: it retraces to here if m1 goes on without it


class _CoarseSight:
    """Sight over ground of 100 m cells (asked every half cell along a step), hidden from x = 20 to 30 m."""

    resolution_m = 100.0

    def __call__(self, a: Point, b: Point, clearance_m: float = 0.0) -> bool:
        return not any(20.0 < p[0] < 30.0 for p in (a, b))


def test_where_the_robot_stands_at_its_next_report_is_judged_wherever_the_samples_fall() -> None:
    sight = _CoarseSight()
    assert roles.link((0.0, 0.0), (100.0, 0.0), (-10.0, 0.0), 500.0, "m1", "", sight) == roles.GO
    v = roles.link((0.0, 0.0), (100.0, 0.0), (-10.0, 0.0), 500.0, "m1", "", sight, run_m=25.0)
    assert v.kind == "hold" and v.reason.startswith("the step would break the link to m1")
    assert roles.link((0.0, 0.0), (100.0, 0.0), (-10.0, 0.0), 500.0, "m1", "", sight, run_m=40.0) == roles.GO
    # the controller's own step alike
    v, robot = roles.control((0.0, 0.0), (100.0, 0.0), [("r1", (-10.0, 0.0))], 500.0, sight, run_m=25.0)
    assert v.kind == "hold" and robot == "r1"


def test_a_robot_that_shuffles_while_held_for_its_link_is_still_waiting() -> None:
    """Held at a crest, closing on its controller for a report and held again: the wait runs on, so a
    team that shuffles between the two is not held for good."""
    team = TeamUpdate(controller="m1", robots=["r1"], radio_range_m=500.0, corridor_m=40.0)
    t = Trails()
    at, to, c = (50.0, 0.0), (80.0, 0.0), (30.0, 0.0)
    assert team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, 0.0)[0].kind == "hold"
    v, _ = team_link.closing_on(t, "r1", at, c, team, _ridge_sight, 20.0)
    assert v.kind == "to" and v.to == c
    assert team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, 40.0)[0].kind == "hold"
    v, _ = team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, LINK_WAIT_S)
    assert v.kind == "to" and v.to == to  # 60 s from its first hold
    # once its link lets it go its way, its next hold waits afresh
    assert (
        team_link.robot_step(t, "r1", (40.0, 0.0), (45.0, 0.0), team, c, "", _ridge_sight, None, 70.0)[0]
        == roles.GO
    )
    assert team_link.robot_step(t, "r1", at, to, team, c, "", _ridge_sight, None, 75.0)[0].kind == "hold"


def test_a_robot_reported_before_its_controller_is_judged_against_the_controllers_step_of_the_same_batch() -> (
    None
):
    """Controllers are judged first: the robot's step keeps where the controller goes this report."""
    from pfp_service.wire import Goal
    from pfp_service.world.team_book import TeamBook
    from pfp_service.world.units import UnitRecord

    book = TeamBook()
    book.put("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=500.0))
    m1 = UnitRecord("m1", 1, position=(0.0, -60.0), goal=Goal(position=(0.0, 500.0)))
    r1 = UnitRecord("r1", 2, position=(60.0, -10.0), goal=Goal(position=(500.0, -10.0)))
    units = {"m1": m1, "r1": r1}
    north, east = _direction("m1", (0.0, 1.0), 20.0), _direction("r1", (1.0, 0.0), 40.0)
    book.judge([east, north], units, _spur_sight, now=0.0)
    m1.position = (0.0, -40.0)  # it went 20 m: its run between reports
    book.judge([east, _direction("m1", (0.0, 0.0), 0.0)], units, _spur_sight, now=5.0)  # then it held
    m1.position = (0.0, 0.0)  # north again; its step of this batch takes it to y = 20
    out = book.judge(
        [_direction("r1", (1.0, 0.0), 40.0), _direction("m1", (0.0, 1.0), 20.0)], units, _spur_sight, now=10.0
    )
    robot = out[0]
    assert robot.unit == "r1" and robot.reach_m is not None and robot.reach_m <= 15.0 + 1e-6, robot
    end = (60.0 + robot.reach_m, -10.0)
    assert _spur_sight((0.0, 20.0), end)  # still seen from where m1 will be
    assert not _spur_sight((0.0, 20.0), (100.0, -10.0))  # where its own step would have taken it


def test_a_robot_going_through_its_controllers_shadow_keeps_on_to_it_until_linked_not_back_out() -> None:
    """Seed 1's r2 (issue 33): half way through the shadow, back along its track would lose it as long again."""
    team = TeamUpdate(controller="m1", robots=["r1"], radio_range_m=500.0)
    t = Trails()

    def pit_sight(a: Point, b: Point, clearance_m: float = 0.0) -> bool:
        """A hollow 20 m round (50, -30) too deep to see out of, the ground round it level."""
        return math.dist(a, (50.0, -30.0)) > 20.0 and math.dist(b, (50.0, -30.0)) > 20.0

    at, c = (35.0, -15.0), (90.0, -70.0)
    team_link.closing_on(t, "r1", at, c, team, pit_sight, 0.0)
    v, _ = team_link.closing_on(t, "r1", at, c, team, pit_sight, LINK_WAIT_S)
    assert v.kind == "to" and v.to == c  # through the shadow, its crumbs kept
    inside, c2 = (50.0, -30.0), (95.0, -70.0)  # in the hollow; m1 no longer holds for it, and went on
    v, pull = team_link.robot_step(t, "r1", inside, (60.0, -30.0), team, c2, "", pit_sight, None, 65.0)
    assert v.kind == "to" and v.to == c2 and not pull, v  # on to m1, not back to (35, -15)
    out_of_it = (70.0, -50.0)  # out of the hollow, linked: its own step is judged again
    v, _ = team_link.robot_step(t, "r1", out_of_it, (80.0, -50.0), team, c2, "", pit_sight, None, 70.0)
    assert v == roles.GO and "r1" not in t.crossing
