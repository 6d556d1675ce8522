"""Compiled walks of a polyline for the team roles: a point's projection, a shared stadium, a capsule run.

A team's follower is judged against its lead's track, which grows a point
every few metres the lead drives (thousands of points): one loop over its
segments a question, with no temporary array per question, where NumPy made
a dozen arrays of the track's length for each.  The arrays are a
``world.teams.Polyline``'s: points ``pts``, segments ``ab``, their squared
lengths ``sq`` (1 for a segment of no length), lengths ``seg``, cumulated
``cum``.  ``extend_one`` grows those arrays by a point in place (``world.team_lines``).
``kept`` is ``world.corridor.Room``'s closed form.  ``places`` is every lead's
place on its main element's route in one call (``world.teams.leads``): the same numbers a
``Polyline`` of each route gives, without making one per lead per tick.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["extend_one", "kept", "place", "places", "project", "project_shared", "shared"]


@numba.njit(cache=True, nogil=True, inline="always")
def _off(
    pts: np.ndarray, ab: np.ndarray, sq: np.ndarray, i: int, px: float, py: float
) -> tuple[float, float]:
    """Where along segment ``i`` (0 to 1) ``(px, py)``'s nearest point lies, and how far off it is."""
    t = ((px - pts[i, 0]) * ab[i, 0] + (py - pts[i, 1]) * ab[i, 1]) / sq[i]
    t = min(max(t, 0.0), 1.0)
    return t, math.hypot(pts[i, 0] + ab[i, 0] * t - px, pts[i, 1] + ab[i, 1] * t - py)


@numba.njit(cache=True, nogil=True)
def project(
    pts: np.ndarray, ab: np.ndarray, sq: np.ndarray, seg: np.ndarray, cum: np.ndarray, px: float, py: float
) -> tuple[float, float]:
    """``(s, d)`` of ``(px, py)`` on a line of two points or more: the first nearest segment's."""
    best, bi, bt = math.inf, 0, 0.0
    for i in range(pts.shape[0] - 1):
        t, off = _off(pts, ab, sq, i, px, py)
        if off < best:
            best, bi, bt = off, i, t
    return cum[bi] + bt * seg[bi], best


@numba.njit(cache=True, nogil=True)
def shared(
    pts: np.ndarray, ab: np.ndarray, sq: np.ndarray, ax: float, ay: float, bx: float, by: float, half: float
) -> bool:
    """Whether both points lie within ``half`` of one segment (its stadium, convex, then holds the step)."""
    for i in range(pts.shape[0] - 1):
        if _off(pts, ab, sq, i, ax, ay)[1] <= half and _off(pts, ab, sq, i, bx, by)[1] <= half:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def project_shared(
    pts: np.ndarray,
    ab: np.ndarray,
    sq: np.ndarray,
    seg: np.ndarray,
    cum: np.ndarray,
    ax: float,
    ay: float,
    bx: float,
    by: float,
    half: float,
    outside: float,
) -> tuple[float, float, bool]:
    """``project`` of ``a``, and, when it lies no further off than ``outside``, ``shared`` of ``a`` and ``b``
    (``False`` when it lies further): a follower's first two questions (``world.teams.follow``) in one
    call, the same numbers.  A micro-optimisation (bench row: BENCHMARKS.md "The judge's members", the
    judge): a follower is judged per report."""
    s, off = project(pts, ab, sq, seg, cum, ax, ay)
    return s, off, not off > outside and shared(pts, ab, sq, ax, ay, bx, by, half)


@numba.njit(cache=True, nogil=True, inline="always")
def _line_in(v0: float, v1: float, lo: float, hi: float) -> tuple[float, float]:
    """The interval of ``t`` where ``v0 + t v1`` lies in ``[lo, hi]`` (empty: ``lo > hi``)."""
    if v1 == 0.0:
        return (-math.inf, math.inf) if lo <= v0 <= hi else (math.inf, -math.inf)
    ta, tb = (lo - v0) / v1, (hi - v0) / v1
    return min(ta, tb), max(ta, tb)


@numba.njit(cache=True, nogil=True, inline="always")
def _disc(px: float, py: float, dx: float, dy: float, cx: float, cy: float, r: float) -> tuple[float, float]:
    """The interval of ``t`` where ``p + t d`` is within ``r`` of ``c`` (empty: ``lo > hi``)."""
    wx, wy = px - cx, py - cy
    dd = dx * dx + dy * dy
    ww = wx * wx + wy * wy - r * r
    if dd == 0.0:
        return (-math.inf, math.inf) if ww <= 0.0 else (math.inf, -math.inf)
    bh = wx * dx + wy * dy
    disc = bh * bh - dd * ww
    if disc < 0.0:
        return math.inf, -math.inf
    root = math.sqrt(disc)
    return (-bh - root) / dd, (-bh + root) / dd


@numba.njit(cache=True, nogil=True)
def kept(
    a: np.ndarray, b: np.ndarray, half: float, px: float, py: float, dx: float, dy: float, eps: float
) -> float:
    """How much (0 to 1) of the step ``p + t d`` (``t`` in 0 to 1) stays in the capsules round the segments
    ``a[k]``-``b[k]`` from its start; intervals ``eps`` apart (a share of the step) join."""
    m = a.shape[0]
    lo = np.empty(m)
    hi = np.empty(m)
    for k in range(m):
        l1, h1 = _disc(px, py, dx, dy, a[k, 0], a[k, 1], half)
        l2, h2 = _disc(px, py, dx, dy, b[k, 0], b[k, 1], half)
        l3, h3 = math.inf, -math.inf
        ex, ey = b[k, 0] - a[k, 0], b[k, 1] - a[k, 1]
        n = math.hypot(ex, ey)
        if n > 0.0:
            ex, ey = ex / n, ey / n
            wx, wy = px - a[k, 0], py - a[k, 1]
            sa, sb = _line_in(wx * ex + wy * ey, dx * ex + dy * ey, 0.0, n)
            ha, hb = _line_in(ex * wy - ey * wx, ex * dy - ey * dx, -half, half)
            l3, h3 = max(sa, ha), min(sb, hb)
        lo_k, hi_k = math.inf, -math.inf  # the union of the pieces the line meets: one interval (convex)
        for s, e in ((l1, h1), (l2, h2), (l3, h3)):
            if s <= e:
                lo_k, hi_k = min(lo_k, s), max(hi_k, e)
        lo[k], hi[k] = lo_k, hi_k
    reach = -math.inf
    for k in range(m):
        if lo[k] <= hi[k] and lo[k] <= eps and hi[k] >= -eps:
            reach = max(reach, hi[k])
    if reach == -math.inf:
        return 0.0  # its start is outside
    order = np.argsort(lo)
    for k in order:
        if reach >= 1.0 or lo[k] > reach + eps:
            break  # past the step's end, or a gap after the run that covers its start
        if lo[k] <= hi[k]:
            reach = max(reach, hi[k])
    return min(reach, 1.0)


@numba.njit(cache=True, nogil=True)
def places(
    pts: np.ndarray, first: np.ndarray, ats: np.ndarray, standoffs: np.ndarray, out: np.ndarray
) -> None:
    """For each route ``k`` (the points ``pts[first[k]:first[k + 1]]``, two or more): its length, where
    ``ats[k]`` projects onto it (``project``'s ``s``) and the point ``standoffs[k]`` along it
    (``Polyline.point_at``), into ``out[k]``; a route no longer than its standoff gets its length alone.

    The arithmetic is ``Polyline``'s, in its order (segments, cumulated lengths, the first nearest
    segment, the segment the standoff ends on), so the numbers are the same.
    """
    for k in range(first.shape[0] - 1):
        _place(pts, first[k], first[k + 1] - first[k], ats[k, 0], ats[k, 1], standoffs[k], out[k])


@numba.njit(cache=True, nogil=True)
def place(pts: np.ndarray, px: float, py: float, standoff: float, out: np.ndarray) -> None:
    """``places`` of one route, all of ``pts`` (two points or more), into ``out`` (4): no arrays made to
    ask it.  A micro-optimisation (bench row: BENCHMARKS.md "A tick's fixed cost", the judge): a live
    tick's reports move a lead or two."""
    _place(pts, 0, pts.shape[0], px, py, standoff, out)


@numba.njit(cache=True, nogil=True, inline="always")
def _place(pts: np.ndarray, a: int, n: int, px: float, py: float, stand: float, out: np.ndarray) -> None:
    """``places``' answer for the route ``pts[a:a + n]`` into ``out`` (4)."""
    seg = np.empty(n - 1)
    cum = np.empty(n)
    cum[0] = 0.0
    for i in range(n - 1):
        seg[i] = math.hypot(pts[a + i + 1, 0] - pts[a + i, 0], pts[a + i + 1, 1] - pts[a + i, 1])
        cum[i + 1] = cum[i] + seg[i]
    out[0] = cum[n - 1]
    out[1:] = math.nan
    if cum[n - 1] <= stand:
        return
    best, bi, bt = math.inf, 0, 0.0
    for i in range(n - 1):
        abx, aby = pts[a + i + 1, 0] - pts[a + i, 0], pts[a + i + 1, 1] - pts[a + i, 1]
        sq = seg[i] * seg[i]
        if not sq > 0.0:  # a segment too short for its square (below 1e-154 m): as a point's
            sq = 1.0
        t = ((px - pts[a + i, 0]) * abx + (py - pts[a + i, 1]) * aby) / sq
        t = min(max(t, 0.0), 1.0)
        off = math.hypot(pts[a + i, 0] + abx * t - px, pts[a + i, 1] + aby * t - py)
        if off < best:
            best, bi, bt = off, i, t
    out[1] = cum[bi] + bt * seg[bi]
    if stand <= 0.0:
        out[2], out[3] = pts[a, 0], pts[a, 1]
        return
    e = np.searchsorted(cum, stand, side="right") - 1  # cum[e] <= stand < cum[e + 1]
    f = (stand - cum[e]) / (cum[e + 1] - cum[e])
    out[2] = pts[a + e, 0] + (pts[a + e + 1, 0] - pts[a + e, 0]) * f
    out[3] = pts[a + e, 1] + (pts[a + e + 1, 1] - pts[a + e, 1]) * f


@numba.njit(cache=True, nogil=True)
def extend_one(
    pts: np.ndarray,
    ab: np.ndarray,
    seg: np.ndarray,
    sq: np.ndarray,
    cum: np.ndarray,
    m: int,
    x: float,
    y: float,
) -> None:
    """A line's arrays of ``m`` points (one or more), held in longer ones, grown by the point ``(x, y)`` in
    place: its segment, length, squared length (1 for none) and cumulated length written after the last,
    ``Polyline``'s arithmetic in its order (``np.diff``, ``np.hypot``, ``_squares``, a running sum), so the
    numbers are a ``Polyline`` of them all's (``world.team_lines``)."""
    pts[m, 0] = x
    pts[m, 1] = y
    ab[m - 1, 0] = pts[m, 0] - pts[m - 1, 0]
    ab[m - 1, 1] = pts[m, 1] - pts[m - 1, 1]
    seg[m - 1] = math.hypot(ab[m - 1, 0], ab[m - 1, 1])
    s2 = seg[m - 1] * seg[m - 1]
    sq[m - 1] = s2 if s2 > 0.0 else 1.0
    cum[m] = cum[m - 1] + seg[m - 1]
