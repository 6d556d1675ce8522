"""What the controllers' links need remembered between reports: each robot's breadcrumbs, each member's run.

A robot that loses its link returns along its own track to the last point where the link held (the
lost-link behaviour of fielded UGVs: retrace the breadcrumbs), not straight at its controller across
ground it never crossed; ``Trails.crumbs`` keeps that track.  A robot and its controller move at once
between two reports, so each one's step is judged against where the other is and against where the
other's direction takes it by the next report (``Trails.ahead``): as far along it as the other went
between its last reports that moved it, no further than the direction's reach.  Pure: positions in,
points out; the team book (``team_book``) feeds it and hands what it says to ``teams.link`` and
``teams.control``.  A robot gone through its controller's shadow to close on it keeps on to it until
linked (``Trails.crossing``): back along its track would lose it as long again.
"""

from __future__ import annotations

import math
from collections import deque

from pfp_service.wire import Direction
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world import teams as roles
from pfp_service.world.teams import Point, Sight, Verdict

__all__ = ["LINK_WAIT_S", "MAX_CRUMBS", "REACHED_M", "Trails", "closing_on", "robot_step"]

# A robot held for its link waits this long for its controller to close on it before it crosses the
# shadow anyway (a crest its controller is beside, or the way to a controller that holds for it): the
# outage is then one the team chose, and said, rather than a team stopped for good.
LINK_WAIT_S = 60.0

MAX_CRUMBS = 256  # a robot's track kept since its link last held, at most: past it, every other point goes
REACHED_M = 2.0  # a breadcrumb this close is reached (a vehicle stops within a few metres of a point)
_RUNS = 4  # a member's run between reports is the longest of its last few that moved it


class Trails:
    """Each robot's breadcrumbs back to where its link last held, and each member's run between reports."""

    def __init__(self) -> None:
        # robot -> its track since its link last held (that point first)
        self.crumbs: dict[str, list[Point]] = {}
        self._was: dict[str, Point] = {}  # member -> where it was at the last judge
        self._runs: dict[str, deque[float]] = {}  # member -> its last runs between reports that moved it
        # member -> the longest of its ``_runs``, taken when one is added: asked several times a judge per
        # member (a micro-optimisation, bench row: ``python -m benchmarks._march_world``, the judge)
        self._longest: dict[str, float] = {}
        self._held_since: dict[str, float] = {}  # robot -> when its link began to hold it, while it does
        self.crossing: set[str] = set()  # robots going through their controller's shadow to it, until linked

    def waiting(self, robot: str, now: float | None) -> float:
        """How long ``robot`` has been held for its link, its hold going on at ``now`` (``None``: no
        clock, so no wait: ``math.inf``)."""
        if now is None:
            return math.inf
        return now - self._held_since.setdefault(robot, now)

    def moving(self, robot: str) -> None:
        """``robot``'s link no longer holds it: its next hold waits afresh."""
        self._held_since.pop(robot, None)

    def moved(self, unit: str, at: Point) -> None:
        """``unit`` is judged at ``at``: how far it went since it was judged last is one of its runs."""
        was = self._was.get(unit)
        if was is not None and was is not at and (run := math.dist(was, at)) > 0.0:
            runs = self._runs.get(unit)
            if runs is None:  # not ``setdefault``: that would make a deque per report to throw away
                runs = self._runs[unit] = deque(maxlen=_RUNS)
            runs.append(run)
            self._longest[unit] = max(runs)
        self._was[unit] = at

    def run(self, unit: str) -> float | None:
        """How far ``unit`` goes between reports (the longest of its last runs), if known."""
        return self._longest.get(unit)

    def ahead(self, unit: str, at: Point, d: Direction | None) -> Point | None:
        """Where ``d`` takes ``unit`` from ``at`` by its next report: ``at`` when it holds, ``None`` when
        how far it goes between reports is not known yet."""
        if d is None or not d.reach_m or not (d.vector[0] or d.vector[1]):
            return at
        run = self.run(unit)
        if run is None:
            return None
        run = min(run, d.reach_m)
        return at[0] + d.vector[0] * run, at[1] + d.vector[1] * run

    def trail(self, robot: str, at: Point, linked: bool) -> list[Point]:
        """The robot's breadcrumbs as it stands at ``at``: its track back to where its link last held (that
        point first), the crumbs it has reached dropped; empty when it is linked, or was never linked."""
        if linked:
            self.crumbs[robot] = [at]
            return []
        trail = self.crumbs.get(robot, [])
        while trail and math.dist(trail[-1], at) < REACHED_M:
            trail.pop()  # reached on its way back
        return list(trail)

    def went_on(self, robot: str, at: Point) -> None:
        """``robot`` goes on from ``at`` where its link does not hold (or will not): ``at`` is a crumb."""
        trail = self.crumbs.get(robot)
        if trail is not None and (not trail or math.dist(trail[-1], at) >= REACHED_M):
            trail.append(at)
            if len(trail) > MAX_CRUMBS:
                trail[1:] = trail[2::2]  # the point where the link held stays first

    def forget(self, units: set[str]) -> None:
        """Drop what is kept of units no longer in a team."""
        for u in units:
            self.crossing.discard(u)
            self.crumbs.pop(u, None)
            self._was.pop(u, None)
            self._runs.pop(u, None)
            self._longest.pop(u, None)
            self._held_since.pop(u, None)


def robot_step(
    trails: Trails,
    robot: str,
    at: Point,
    to: Point,
    team: TeamUpdate,
    c_at: Point | None,
    lost: str,
    sight: Sight | None,
    c_dir: Direction | None,
    now: float | None,
) -> tuple[Verdict, bool]:
    """A robot's step to ``to`` judged for its link (``teams.link``), with its breadcrumbs and its
    controller's own step; and whether its controller is to close on it (its link holds it).

    A robot held for its link holds while its controller closes on it; one its controller is already
    beside (within ``corridor_m``) crosses the crest after ``LINK_WAIT_S`` (a lead held at a crest, its
    controller behind it on the ground it cleared, held for ever without it).
    """
    ctl = str(team.controller)
    if c_at is None or lost:
        return roles.link(at, to, c_at, team.radio_range_m, ctl, lost, sight), False
    here = roles.in_link(c_at, at, team.radio_range_m, sight)
    if robot in trails.crossing:
        if not here:  # half way through the shadow: back along its track would lose it as long again
            trails.went_on(robot, at)
            return Verdict("to", c_at, f"closing on {ctl} through its shadow"), False
        trails.crossing.discard(robot)
    back = trails.trail(robot, at, here)
    c_next, run = trails.ahead(ctl, c_at, c_dir), trails.run(robot)
    v = roles.link(at, to, c_at, team.radio_range_m, ctl, lost, sight, c_next, back, run)
    if v.kind != "hold":
        # its wait is over once its link lets it go its way as far as a report takes it (not while it
        # retraces, closes on its controller or creeps: a team that shuffles is still held)
        if here and (v.kind == "go" or (v.to is not None and math.dist(at, v.to) >= (run or 0.0))):
            trails.moving(robot)
        return v, False
    waited = trails.waiting(robot, now)
    if math.dist(at, c_at) <= team.corridor_m and waited >= LINK_WAIT_S:
        why = f"out of {ctl}'s sight over the crest beside it: it follows{_after(waited)}"
        trails.went_on(robot, at)
        return Verdict("to", to, f"{v.reason}; {why}"), True
    return v, True


def closing_on(
    trails: Trails, robot: str, at: Point, c: Point, team: TeamUpdate, sight: Sight | None, now: float | None
) -> tuple[Verdict, bool]:
    """A robot whose controller holds for its link makes for the controller; and whether the controller is
    to close on it too: where the way leaves its sight at once, the robot holds for ``LINK_WAIT_S`` while
    the controller comes, then goes on through the shadow (its crumbs kept, to retrace if the controller
    goes on without it)."""
    ctl = str(team.controller)
    why = f"closing on {ctl}, which holds for its link"
    trails.trail(robot, at, roles.in_link(c, at, team.radio_range_m, sight))  # linked: its crumbs start here
    v = roles.link(at, c, c, team.radio_range_m, ctl, "", sight)
    if v.kind == "go":
        return Verdict("to", c, why), False
    if v.kind == "to" and v.to is not None:
        if v.to == c:  # out of its link already, on its way to it
            trails.went_on(robot, at)
        return Verdict("to", v.to, f"{why}; {v.reason}"), False
    waited = trails.waiting(robot, now)
    if waited < LINK_WAIT_S:
        return Verdict("hold", None, f"{why}: its way leaves {ctl}'s sight, so {ctl} closes on it"), True
    trails.went_on(robot, at)
    trails.crossing.add(robot)
    return Verdict("to", c, f"{why}; through {ctl}'s shadow{_after(waited)}"), True


def _after(waited: float) -> str:
    return f" after {waited:,.0f} s" if math.isfinite(waited) else ""
