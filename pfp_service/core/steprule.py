"""The step rule, written once: judge a unit where it stands, and say where one step takes it.

``judge`` is the one compiled function that holds the arrival, bounds and
trap rules and the step ``x += move * direction``.  Every driver calls it:
the stepper (``Stepper.advise``, live and preview, through ``descend``), the
batched look-ahead (``cull.predict``), the foresight simulation
(``foresight.simulate``) and the route walkers (``escape_strategies.rollout``,
``EscapeRun.ahead``).  Python never steps a unit itself: a driver moves a
unit to ``Advice.to``, which ``judge`` computed.

A unit travels as one float64 array (``unit``): its goal, goal gain,
tolerance, step, bounds and trap windows (``UNIT_COLUMNS``), then its trap
watch: the best distance so far, the advisories since it improved, and a
ring of the last ``trap_window`` positions.  A unit made with ``watch=False``
has no ring and is never judged trapped by the watch (a look-ahead, a
rollout).

The rules, in order:

1. a position that is not finite is ``BAD_POSITION``;
2. within ``tolerance`` of the goal is ``ARRIVED``;
3. outside the bounds is ``OUT_OF_BOUNDS``;
4. (descent) a gradient that is not finite is ``BAD_GRADIENT``, a vanishing
   one ``STATIONARY``; the direction is ``-grad f / |grad f|``;
   (heading) the direction is the one given (a route's);
5. the final approach: with the goal within one step, the step goes straight
   to the goal and ends on it (a full step would overshoot, then bounce
   across it and never come within a tolerance under half a step);
6. (descent, watched) *no progress*: the best distance has not improved by
   ``tolerance`` in ``progress_window`` advisories; *oscillating*: the unit
   is less than ``0.2 * trap_window * step`` from where it was
   ``trap_window`` advisories ago.  A watch verdict still carries the
   direction and the step (a deferring stepper descends on meanwhile).

The zone rule (``judge_zoned``, which every descent driver calls instead of
``judge``; with no zones it is ``judge``): keep-out zones (``core.zones``)
add a smooth barrier to the gradient within ``BARRIER_STEPS`` steps of a
zone, ``BARRIER_PUSH * |grad f| * (1 - d / rho)^2`` along the outward normal,
so descent bends away by itself (at a zone's edge the barrier pushes out
twice as hard as the rest of the field pulls); and a step that would touch a
zone is cut to end ``CLEAR_STEPS`` steps short of it.  A unit that cannot
move on is then caught by the trap watch like any other (and escapes round).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core import kernels, zones

__all__ = [
    "ARRIVED",
    "BAD_GRADIENT",
    "BAD_POSITION",
    "BARRIER_PUSH",
    "BARRIER_STEPS",
    "CHECK",
    "CLEAR_STEPS",
    "DESCENT",
    "GO",
    "HEADING",
    "NO_PROGRESS",
    "OSCILLATING",
    "OUT_OF_BOUNDS",
    "RING",
    "RING_START",
    "STATIONARY",
    "UNIT_COLUMNS",
    "descend",
    "judge",
    "judge_zoned",
    "reset_watch",
    "roomy",
    "unit",
]

UNIT_COLUMNS = (
    "goal_x", "goal_y", "gain", "tolerance", "step", "lo_x", "lo_y", "hi_x", "hi_y",
    "window", "patience", "best", "since", "count", "head",
)  # fmt: skip
GOAL_X, GOAL_Y, GAIN, TOL, STEP, LO_X, LO_Y, HI_X, HI_Y, WINDOW, PATIENCE, BEST, SINCE, COUNT, HEAD = range(
    len(UNIT_COLUMNS)
)
RING = len(UNIT_COLUMNS)  # the watch's ring of recent positions starts here, x and y interleaved
RING_START = 64  # positions a ring holds at first: it grows (``roomy``) up to ``trap_window``

# What ``judge`` is asked: arrival and bounds only; a descent step (given grad f); a step along a heading.
CHECK, DESCENT, HEADING = range(3)
# What it says: go on, or why not.
GO, ARRIVED, OUT_OF_BOUNDS, BAD_POSITION, BAD_GRADIENT, STATIONARY, NO_PROGRESS, OSCILLATING = range(8)

Bounds = tuple[tuple[float, float], tuple[float, float]]

BARRIER_STEPS = 3.0  # the zone barrier reaches this many steps from a zone
BARRIER_PUSH = 2.0  # at a zone's edge, how many times the rest of the gradient it pushes out
CLEAR_STEPS = 0.1  # a step cut at a zone ends this many steps short of it


def unit(
    goal: tuple[float, float],
    gain: float,
    tolerance: float,
    step: float,
    bounds: Bounds | None = None,
    trap_window: int = 0,
    progress_window: int = 0,
    watch: bool = True,
) -> np.ndarray:
    """A unit for ``judge``: its goal and rules, and a fresh trap watch (none when not ``watch``)."""
    (x0, y0), (x1, y1) = bounds if bounds is not None else ((-math.inf, -math.inf), (math.inf, math.inf))
    window = trap_window if watch else 0
    u = np.empty(RING + 2 * min(window, RING_START))
    u[:RING] = (goal[0], goal[1], gain, tolerance, step, x0, y0, x1, y1, window, progress_window, 0, 0, 0, 0)
    reset_watch(u)
    return u


def reset_watch(u: np.ndarray) -> None:
    """Judge progress afresh from here: forget the best distance and the recent positions."""
    u[BEST] = math.inf
    u[SINCE] = 0.0
    u[COUNT] = 0.0
    u[HEAD] = 0.0


def roomy(u: np.ndarray) -> np.ndarray:
    """``u``, or a copy with a larger ring when the next watched step needs one (rare: a long ``trap_window``)."""
    cap = (len(u) - RING) // 2
    if u[COUNT] < cap or cap >= u[WINDOW]:
        return u
    bigger = np.empty(RING + 2 * min(int(u[WINDOW]), 2 * cap))
    bigger[: len(u)] = u
    return bigger


@numba.njit(cache=True, nogil=True, inline="always")
def judge(
    u: np.ndarray, x: float, y: float, fx: float, fy: float, norm: float, mode: int
) -> tuple[int, float, float, float, float, float, float]:
    """The one step rule for unit ``u`` at ``(x, y)`` (module docstring).

    Args:
        u: the unit (``unit``); its watch is updated in place under ``DESCENT``.
        fx, fy, norm: ``DESCENT``: the potential's gradient and its norm;
            ``HEADING``: a unit direction (``norm`` unused); ``CHECK``: unused.
        mode: ``CHECK``, ``DESCENT`` or ``HEADING``.

    Returns:
        ``(code, dx, dy, dist, move, to_x, to_y)``: the verdict, the direction
        (zero for a verdict that ends the walk), the distance to the goal, and
        the step: its length and where it ends (the position itself when
        there is none).
    """
    gx = u[GOAL_X]
    gy = u[GOAL_Y]
    dist = math.hypot(gx - x, gy - y)
    if not (math.isfinite(x) and math.isfinite(y)):
        return BAD_POSITION, 0.0, 0.0, dist, 0.0, x, y
    if dist <= u[TOL]:
        return ARRIVED, 0.0, 0.0, dist, 0.0, x, y
    if not (u[LO_X] <= x <= u[HI_X] and u[LO_Y] <= y <= u[HI_Y]):
        return OUT_OF_BOUNDS, 0.0, 0.0, dist, 0.0, x, y
    if mode == CHECK:
        return GO, 0.0, 0.0, dist, 0.0, x, y
    if mode == HEADING:
        dx = fx
        dy = fy
    else:
        if not math.isfinite(norm):
            return BAD_GRADIENT, 0.0, 0.0, dist, 0.0, x, y
        if norm == 0.0:
            return STATIONARY, 0.0, 0.0, dist, 0.0, x, y
        dx = -fx / norm
        dy = -fy / norm
    step = u[STEP]
    if dist <= step and dist > 0.0:  # the final approach: straight onto the goal
        move = dist
        dx = (gx - x) / dist
        dy = (gy - y) / dist
        to_x = gx
        to_y = gy
    else:
        move = step
        to_x = x + move * dx
        to_y = y + move * dy
    if mode == HEADING or u[WINDOW] == 0.0:
        return GO, dx, dy, dist, move, to_x, to_y
    # the trap watch: no progress, then oscillation
    if dist < u[BEST] - u[TOL]:
        u[BEST] = dist
        u[SINCE] = 0.0
    else:
        u[SINCE] += 1.0
        if u[SINCE] >= u[PATIENCE]:
            return NO_PROGRESS, dx, dy, dist, move, to_x, to_y
    window = int(u[WINDOW])
    count = int(u[COUNT])
    head = int(u[HEAD])
    if count == window:
        ox = u[RING + 2 * head]
        oy = u[RING + 2 * head + 1]
        if math.hypot(x - ox, y - oy) < 0.2 * window * step:
            return OSCILLATING, dx, dy, dist, move, to_x, to_y
    u[RING + 2 * head] = x
    u[RING + 2 * head + 1] = y
    u[HEAD] = (head + 1) % window
    u[COUNT] = min(count + 1, window)
    return GO, dx, dy, dist, move, to_x, to_y


@numba.njit(cache=True, nogil=True)
def judge_zoned(
    u: np.ndarray,
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    x: float,
    y: float,
    fx: float,
    fy: float,
    norm: float,
) -> tuple[int, float, float, float, float, float, float]:
    """``judge`` of a descent advisory under keep-out zones (the zone rule, module docstring).

    Args:
        edges, offsets, circles, boxes: the zones (``ZoneSet.packed()``; empty arrays for none).
        fx, fy, norm: the potential's gradient at ``(x, y)`` without the zones, and its norm.

    Returns:
        As ``judge``: the direction bent by the barrier, the step cut short of any zone.
    """
    if boxes.shape[0] > 0 and math.isfinite(norm):
        rho = BARRIER_STEPS * u[STEP]
        sd, z, gx, gy = zones.point_zone(edges, offsets, circles, boxes, x, y, rho)
        if z >= 0 and sd < rho:
            s = 1.0 - max(sd, 0.0) / rho
            push = BARRIER_PUSH * norm * s * s
            fx = fx - push * gx
            fy = fy - push * gy
            norm = math.hypot(fx, fy)
    code, dx, dy, dist, move, to_x, to_y = judge(u, x, y, fx, fy, norm, DESCENT)
    if boxes.shape[0] > 0 and move > 0.0 and (code == GO or code >= NO_PROGRESS):
        t, z = zones.segment_hit(edges, offsets, circles, boxes, x, y, to_x, to_y)
        if z >= 0:
            keep = max(t * move - CLEAR_STEPS * u[STEP], 0.0)
            to_x = x + dx * keep
            to_y = y + dy * keep
            move = keep
    return code, dx, dy, dist, move, to_x, to_y


@numba.njit(cache=True, nogil=True)
def descend(
    packed: np.ndarray,
    edges: np.ndarray,
    offsets: np.ndarray,
    circles: np.ndarray,
    boxes: np.ndarray,
    u: np.ndarray,
    x: float,
    y: float,
) -> tuple[int, float, float, float, float, float, float, float]:
    """One descent advisory in one call: the potential's gradient at ``(x, y)`` (``kernels.point_descent``), judged.

    Args:
        edges, offsets, circles, boxes: the keep-out zones (``ZoneSet.packed()``), judged by ``judge_zoned``.

    Returns:
        ``(code, dx, dy, level, dist, move, to_x, to_y)``: ``judge_zoned``'s answer
        with the threat level at ``(x, y)``.
    """
    fx, fy, level, norm = kernels.point_descent(packed, x, y, u[GOAL_X], u[GOAL_Y], u[GAIN])
    code, dx, dy, dist, move, to_x, to_y = judge_zoned(u, edges, offsets, circles, boxes, x, y, fx, fy, norm)
    return code, dx, dy, level, dist, move, to_x, to_y
