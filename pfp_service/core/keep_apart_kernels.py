"""Compiled keep-apart cut for ``world.keep_apart``: a tick's directions against their neighbours' discs in one pass.

``keep_apart.cut`` is dispersion's last word on a moving direction: each
pair's entry into the neighbour's disc, lengthened where the neighbour goes
the unit's way, each unit's nearest entry, and the pairs that hold each
other.  A live tick has a few reports, so a few pairs, and as NumPy that
was some fifty calls on arrays of a dozen rows, each paying NumPy's cost
of a call more than its arithmetic.  Here it is one call, a pair at a
time.  A micro-optimisation, issue 33 (bench row: BENCHMARKS.md
"keep_apart's cut compiled (issue 33)", ``python -m benchmarks._march_world
--tick 8``).  No fast-math: NumPy's floating-point operations in its order
(a row's ``(a * b).sum(axis=1)`` is ``a0 * b0 + a1 * b1``, ``np.hypot`` and
``np.sqrt`` are ``math``'s), so the same numbers;
``tests/unit/test_keep_apart_kernels.py`` holds the NumPy they stand for.

The rule's constants (``keep_apart``'s ``KEEP``, ``GIVEN``, ``INSIDE``,
``WITH`` and its grazing tolerance) come in as one tuple, ``rule``: a
constant read from another module would be frozen into numba's cache,
which does not see that module change.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pfp_service.core.neighbour_kernels import _larger, _smaller

__all__ = ["cut", "entries"]

Rule = tuple[float, float, float, float, float]  # keep, given, inside, with, graze_m: ``keep_apart``'s


@numba.njit(cache=True, nogil=True, inline="always")
def _entry(
    points: np.ndarray, a: int, b: int, s: float, vx: float, vy: float, gives: bool, rule: Rule
) -> float:
    """How far along ``(vx, vy)`` unit ``a`` enters ``b``'s disc (``s``: the pair's separation; ``gives``:
    ``a`` gives way to ``b``); ``inf``: never."""
    keep, given, inside, _, graze = rule
    rx = points[b, 0] - points[a, 0]
    ry = points[b, 1] - points[a, 1]
    along = rx * vx + ry * vy
    keep_m = given * s if gives else keep * s
    gap2 = rx * rx + ry * ry
    if math.sqrt(gap2) <= keep_m + graze:  # on the disc's edge (where the cut parks it) or inside it
        keep_m = _smaller(keep_m, inside * s)
    across2 = gap2 - along * along
    if along > graze and across2 < keep_m * keep_m:
        return _larger(along - math.sqrt(_larger(keep_m * keep_m - across2, 0.0)), 0.0)
    return math.inf


@numba.njit(cache=True, nogil=True, inline="always")
def _ray(rx: float, ry: float, ux: float, uy: float, keep: float, graze: float) -> float:
    """The first ``t >= 0`` (in lengths of ``u``) where ``|rel - t u| < keep``; ``inf``: never."""
    a = ux * ux + uy * uy
    b = rx * ux + ry * uy
    c = (rx * rx + ry * ry) - keep * keep
    disc = b * b - a * c
    if b > graze and disc > 0.0 and a > 0.0:
        return _larger((b - math.sqrt(disc)) / a, 0.0)
    return math.inf


@numba.njit(cache=True, nogil=True, inline="always")
def _along(
    rx: float, ry: float, vx: float, vy: float, wx: float, wy: float, cap: float, keep: float, graze: float
) -> float:
    """How far a unit goes along ``v`` before it is within ``keep`` of a neighbour at ``rel`` that goes
    along ``w`` at the unit's speed for ``cap`` metres, then stands."""
    dx = vx - wx
    dy = vy - wy
    first = _ray(rx, ry, dx, dy, keep, graze)
    rest = cap + _ray(rx - cap * dx, ry - cap * dy, vx, vy, keep, graze)
    return first if first <= cap else rest


@numba.njit(cache=True, nogil=True, inline="always")
def _nearest(enter: np.ndarray, i: np.ndarray, at: np.ndarray, count: int) -> np.ndarray:
    """Each of ``count`` moving units' nearest entry into a disc: the least finite ``enter`` of its pairs."""
    safe = np.full(count, math.inf)
    for k in range(i.shape[0]):
        e = enter[k]
        if math.isfinite(e):
            n = at[i[k]]
            safe[n] = _smaller(safe[n], e)
    return safe


@numba.njit(cache=True, nogil=True, error_model="numpy")
def entries(
    points: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    pair_s: np.ndarray,
    vec: np.ndarray,
    gives_way: np.ndarray,
    rule: Rule,
    out: np.ndarray,
) -> None:
    """How far along ``vec[k]`` each unit ``i[k]`` enters ``j[k]``'s disc, into ``out[k]`` (``inf``: never).

    ``gives_way``: each row's unit it gives way to (``-1``: none); empty when no unit does."""
    gives = gives_way.shape[0] > 0
    for k in range(i.shape[0]):
        a, b = i[k], j[k]
        out[k] = _entry(points, a, b, pair_s[k], vec[k, 0], vec[k, 1], gives and gives_way[b] == a, rule)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def cut(
    points: np.ndarray,
    rows: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    pair_s: np.ndarray,
    ways: np.ndarray,
    gives_way: np.ndarray,
    rule: Rule,
    enter: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``keep_apart.cut``'s numbers: each moving unit's nearest entry into a disc, and the pairs held.

    Args:
        points: the index's points.
        rows: each moving unit's row in ``points``.
        i, j, pair_s: the pairs of ``rows`` with their neighbours (``NeighbourIndex.near_seps``).
        ways: per moving unit, ``(vx, vy, own, told)``: its direction's vector, 1.0 when it is on its
            own way in this tick (0.0: not), and its reach as told (0.0: none).
        gives_way: each row's unit it gives way to (``-1``: none); empty when no unit does.
        rule: ``keep_apart``'s ``(KEEP, GIVEN, INSIDE, WITH, graze_m)``.
        enter: each pair's entry, written here: with every neighbour standing, lengthened where the
            neighbour goes the unit's way (``keep_apart``'s docstring: a neighbour going the unit's
            way moves too).

    Returns:
        Each moving unit's nearest entry (``inf``: none), and the held pairs ``(m, j)`` (the moving
        unit's place in ``rows``, the neighbour's row), in the pairs' order.
    """
    keep, given, _, with_dot, graze = rule
    count = rows.shape[0]
    at = np.full(points.shape[0], -1, dtype=np.intp)
    for m in range(count):
        at[rows[m]] = m
    gives = gives_way.shape[0] > 0
    for k in range(i.shape[0]):
        a, b, n = i[k], j[k], at[i[k]]
        enter[k] = _entry(points, a, b, pair_s[k], ways[n, 0], ways[n, 1], gives and gives_way[b] == a, rule)
    standing = _nearest(enter, i, at, count)
    for k in range(i.shape[0]):  # the neighbour going the unit's way, both on their own ways: it moves too
        a, b = i[k], j[k]
        n, m = at[a], at[b]
        if m < 0 or ways[m, 2] == 0.0 or ways[n, 2] == 0.0:
            continue
        vx, vy, wx, wy = ways[n, 0], ways[n, 1], ways[m, 0], ways[m, 1]
        if not wx * vx + wy * vy > with_dot:
            continue
        cap = _smaller(ways[m, 3], standing[m])  # how far it goes at least: as told, cut with all standing
        rx = points[b, 0] - points[a, 0]
        ry = points[b, 1] - points[a, 1]
        s = pair_s[k]
        near = given * s if math.hypot(rx, ry) <= keep * s + graze else keep * s
        moving = _smaller(
            _along(rx, ry, vx, vy, wx, wy, cap, near, graze), _ray(rx, ry, vx, vy, given * s, graze)
        )
        enter[k] = _larger(enter[k], moving)
    safe = _nearest(enter, i, at, count)
    held = np.empty((i.shape[0], 2), dtype=np.intp)
    h = 0
    for k in range(i.shape[0]):
        n = at[i[k]]
        if enter[k] <= graze and safe[n] <= graze:
            held[h, 0], held[h, 1] = n, j[k]
            h += 1
    return safe, held[:h]
