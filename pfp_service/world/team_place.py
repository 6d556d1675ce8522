"""A controller's place among its robots: where it steps when the step it planned would lose one of them.

A controller of two robots that holds or cuts its step for one, or closes on one while another's link
holds that one, is pulled by each in turn: between its lead and its second robot across a crest, it
stepped toward each and back, and one of them went through its shadow (issue 33, seed 1 of
``pfp bench teams --terrain``).  Instead, ``control`` tries a small fixed set of places round it
with the world's own link test (range, and the exact sight line from its own height to each robot's): ``HEADINGS`` headings at a
report's run and at half of it (its own way first), and the way to each robot and to their middle.
It steps to the place that links the most of its robots, keeping every link it has along the way
and at its next report's point (as ``teams.control`` judges a step), on ground it may enter (a
follower's cleared corridor); of those, the one nearest the end of its own step.  A place must be
better than the step as judged (more robots linked at its end, or at least ``_BETTER_M`` nearer its
own way), or the verdict stands, with its holds and waits.  Bounded: ``HEADINGS * 2 + robots + 1``
places per controller and report at most, tried only when its step is held, cut, or ends with a
robot out of link; no search.  Pure, as ``teams`` is.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Mapping, Sequence

import numpy as np

from pfp_service.world import teams as roles
from pfp_service.world.polyline import Polyline
from pfp_service.world.polyline import dist as _dist
from pfp_service.world.teams import GO, Point, Sight, Verdict

__all__ = ["HEADINGS", "control", "place"]

HEADINGS = 8  # headings tried round a controller, its own way first: 45° apart
_SHARES = (1.0, 0.5)  # of a report's run: the rings of places tried
_BETTER_M = 1.0  # a place with no more robots linked is taken only this much nearer its own way
_CLOSE_M = 1.0  # a place this close to where the controller is: it is there


def control(
    at: Point,
    to: Point,
    robots: Sequence[tuple[str, Point]],
    radio_range_m: float,
    sight: Sight | None = None,
    next_of: Mapping[str, Point] | None = None,
    run_m: float | None = None,
    closing: tuple[str, Point] | None = None,
    ground: tuple[Polyline, float] | None = None,
    sights: Mapping[str, Sight] | None = None,
) -> tuple[Verdict, str]:
    """``teams.control``'s verdict on the controller's step to ``to``, replaced by a step to a better place
    among its robots (``place``) where there is one.

    Args:
        closing: the robot the controller closes on, when it does (its link holds it): judged with
            ``robots`` (the others) for the place, not for the step.
        ground: a follower's cleared corridor (its lead's track, its width): the places it may enter.
        sights: a robot's own sight line, each end at its unit's height (``team_masts``), over ``sight``.

    Returns:
        ``(verdict, robot)`` as ``teams.control``'s, the robot ``""`` when a place was chosen.
    """
    v, robot = roles.control(at, to, robots, radio_range_m, sight, next_of, run_m, sights)
    every = [*robots, closing] if closing is not None else list(robots)
    better = place(at, to, v, every, radio_range_m, sight, next_of, run_m, ground, sights)
    return (v, robot) if better is None else (better, "")


def place(
    at: Point,
    to: Point,
    judged: Verdict,
    robots: Sequence[tuple[str, Point]],
    radio_range_m: float,
    sight: Sight | None = None,
    next_of: Mapping[str, Point] | None = None,
    run_m: float | None = None,
    ground: tuple[Polyline, float] | None = None,
    sights: Mapping[str, Sight] | None = None,
) -> Verdict | None:
    """The step to the best place round ``at`` for a controller of two robots or more, or ``None`` when the
    step as ``judged`` (``teams.control``'s verdict on the step to ``to``) is as good.

    A place is taken only when the straight step to it keeps every robot linked at ``at`` linked (and
    its next point, ``next_of``: ``teams.control``), and it lies on ``ground`` where that is given.
    Each robot's sight line is its own in ``sights`` (each end at its unit's height), else ``sight``.
    """

    def seen_by(rid: str) -> Sight | None:
        return sights.get(rid, sight) if sights else sight

    if len(robots) < 2:
        return None
    end = at if judged.kind == "hold" else (judged.to if judged.to is not None else to)

    if sight is None and not sights:  # ``in_link`` inlined, its very numbers: asked per controller and report
        hypot = math.hypot
        linked_end = sum(1 for _, q in robots if hypot(q[0] - end[0], q[1] - end[1]) <= radio_range_m)
    else:
        linked_end = sum(roles.in_link(end, q, radio_range_m, seen_by(rid)) for rid, q in robots)
    if judged.kind == "go" and linked_end == len(robots):
        return None  # its own step keeps them all
    base = (linked_end, -_dist(end, to))
    pts = np.array([p for _, p in robots], dtype=float)
    cs = [(float(x), float(y)) for x, y in _places(at, to, pts, run_m)]
    # each place's distance to each robot at once: its robots in range bound its robots linked, so the
    # places are taken best first and a place's sight lines are asked only when it may be the best
    xy = np.array(cs)
    near = np.hypot(xy[:, None, 0] - pts[None, :, 0], xy[:, None, 1] - pts[None, :, 1]) <= radio_range_m
    heap = [
        (-int(near[k].sum()), _dist(c, to), k, False)
        for k, c in enumerate(cs)
        if _dist(at, c) >= _CLOSE_M and _dist(c, end) >= _CLOSE_M
    ]
    heapq.heapify(heap)
    while heap:
        neg, far, k, asked = heapq.heappop(heap)
        if -neg < base[0] or (-neg == base[0] and -far <= base[1] + _BETTER_M):
            return None  # no place left is better than the step as judged
        c = cs[k]
        if not asked:
            if ground is None or _on(ground, at, c):
                linked_here = sum(
                    1
                    for j in np.flatnonzero(near[k]).tolist()
                    if (s := seen_by(robots[j][0])) is None or s(c, robots[j][1])
                )
                heapq.heappush(heap, (-linked_here, far, k, True))
            continue
        if roles.control(at, c, robots, radio_range_m, sight, next_of, run_m, sights)[0] == GO:
            ids = ", ".join(rid for rid, _ in robots)
            what = f"{ids} linked" if -neg == len(robots) else f"{-neg} of {ids} linked"
            why = f"to a place that keeps {what}"
            return Verdict("to", c, f"{judged.reason}; {why}" if judged.reason else why)
    return None


def _places(at: Point, to: Point, robots: np.ndarray, run_m: float | None) -> list[Point]:
    """The places tried: rings at a report's run (its step's length where that is not known: a step cut
    short, or closing on a robot near it, still tries a report's way round it) and half of it,
    ``HEADINGS`` headings from its own way; the way to each robot and to their middle, as far."""
    far = _dist(at, to)
    reach = max(run_m if run_m is not None and run_m > 0.0 else far, _CLOSE_M)
    own = math.atan2(to[1] - at[1], to[0] - at[0]) if far > 0.0 else 0.0
    angles = own + 2.0 * math.pi * np.arange(HEADINGS) / HEADINGS
    out = [
        (at[0] + math.cos(a) * reach * s, at[1] + math.sin(a) * reach * s)
        for s in _SHARES
        for a in angles.tolist()
    ]
    for t in [*robots.tolist(), robots.mean(axis=0).tolist()]:
        d = math.hypot(t[0] - at[0], t[1] - at[1])
        f = min(1.0, reach / d) if d > 0.0 else 0.0
        out.append((at[0] + (t[0] - at[0]) * f, at[1] + (t[1] - at[1]) * f))
    return out


def _on(ground: tuple[Polyline, float], at: Point, c: Point) -> bool:
    """Whether a follower's straight step to ``c`` stays on the ground its lead cleared (``teams.follow``)."""
    line, corridor_m = ground
    return roles.follow(at, c, line, corridor_m, "", "") == GO
