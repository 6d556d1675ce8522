"""The ground a lead has cleared near a follower, as capsules: how much of a straight step stays on it.

A lead's track buffered by half the corridor is the union of one capsule
(a segment's points within ``half``) per segment.  A step's line meets a
capsule, which is convex, in one interval of the step; the part of the step
kept from its start is the run of those intervals that covers its start.
Exact, in closed form and vectorised over the segments near the step: no
polygon is built (a buffer's polygon is inscribed in the capsules, its arcs
chords, so the two differ at the corridor's rounded edges by a fraction of a
percent of its width, less than the margin ``teams.follow`` keeps inside it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["Room", "near"]

Point = tuple[float, float]

_T_EPS = 1e-9  # intervals this close (a share of the step) join: a step along a segment's end is one run


class Room:
    """The capsules of radius ``half`` round the segments ``a[k]``-``b[k]`` (a point: ``a[k] == b[k]``)."""

    __slots__ = ("a", "b", "half")

    def __init__(self, a: np.ndarray, b: np.ndarray, half: float) -> None:
        self.a, self.b, self.half = a, b, half

    def kept(self, at: Point, to: Point) -> float:
        """How much (0 to 1) of the straight step from ``at`` to ``to`` stays in the room from its start."""
        if len(self.a) == 0:
            return 0.0
        lo, hi = self._spans(np.asarray(at, dtype=float), np.asarray(to, dtype=float) - np.asarray(at))
        ok = lo <= hi
        lo, hi = lo[ok], hi[ok]
        start = (lo <= _T_EPS) & (hi >= -_T_EPS)
        if not np.any(start):
            return 0.0  # its start is outside
        reach = float(hi[start].max())  # a step of no length inside: inf
        for s, e in zip(*(x.tolist() for x in (lo[np.argsort(lo)], hi[np.argsort(lo)]))):
            if reach >= 1.0 or s > reach + _T_EPS:
                break  # past the step's end, or a gap after the run that covers its start
            reach = max(reach, e)
        return min(reach, 1.0)

    def _spans(self, p: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each capsule's interval of ``t`` on the line ``p + t d`` (empty: ``lo > hi``); a step of no
        length is all of the line (``-inf``, ``inf``) inside a capsule, and empty outside it."""
        a, b, r = self.a, self.b, self.half
        los, his = (np.stack(x) for x in zip(_disc(p, d, a, r), _disc(p, d, b, r), _slab(p, d, a, b, r)))
        empty = los > his  # a piece the line misses: out of the union, whatever its bounds
        return np.where(empty, np.inf, los).min(axis=0), np.where(empty, -np.inf, his).max(axis=0)


def _disc(p: np.ndarray, d: np.ndarray, c: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """The interval of ``t`` where ``p + t d`` is within ``r`` of each ``c`` (empty as ``inf``, ``-inf``)."""
    w = p - c
    dd = float(d @ d)
    ww = (w * w).sum(axis=1) - r * r
    if dd == 0.0:
        inside = ww <= 0.0
        return np.where(inside, -np.inf, np.inf), np.where(inside, np.inf, -np.inf)
    bh = w @ d
    disc = bh * bh - dd * ww
    root = np.sqrt(np.maximum(disc, 0.0))
    ok = disc >= 0.0
    return np.where(ok, (-bh - root) / dd, np.inf), np.where(ok, (-bh + root) / dd, -np.inf)


def _slab(
    p: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray, r: float
) -> tuple[np.ndarray, np.ndarray]:
    """The interval of ``t`` where ``p + t d`` is in each segment's rectangle (its points within ``r``,
    projecting onto it); empty for a segment of no length (its discs are all of its capsule)."""
    ab = b - a
    seg = np.hypot(ab[:, 0], ab[:, 1])
    live = seg > 0.0
    e = ab / np.where(live, seg, 1.0)[:, None]
    w = p - a
    s0, s1 = (w * e).sum(axis=1), d @ e.T  # along the segment: s0 + t s1 in [0, seg]
    h0 = e[:, 0] * w[:, 1] - e[:, 1] * w[:, 0]  # across it: h0 + t h1 in [-r, r]
    h1 = e[:, 0] * d[1] - e[:, 1] * d[0]
    lo1, hi1 = _within(s0, s1, 0.0, seg)
    lo2, hi2 = _within(h0, h1, -r, r)
    lo, hi = np.maximum(lo1, lo2), np.minimum(hi1, hi2)
    return np.where(live, lo, np.inf), np.where(live, hi, -np.inf)


def _within(
    v0: np.ndarray, v1: np.ndarray, lo: float | np.ndarray, hi: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The interval of ``t`` where ``v0 + t v1`` lies in ``[lo, hi]``."""
    flat = v1 == 0.0
    inside = (v0 >= lo) & (v0 <= hi)
    safe = np.where(flat, 1.0, v1)
    ta, tb = (lo - v0) / safe, (hi - v0) / safe
    t0, t1 = np.minimum(ta, tb), np.maximum(ta, tb)
    return (
        np.where(flat, np.where(inside, -np.inf, np.inf), t0),
        np.where(flat, np.where(inside, np.inf, -np.inf), t1),
    )


def near(track: Sequence[Point] | np.ndarray, half: float, at: Point, reach: float) -> Room:
    """The corridor (``track`` buffered by ``half``) where a step of ``reach`` from ``at`` can go.

    Only the track's segments whose boxes come within that reach are kept, so the cost is the step's, not the
    track's.
    """
    pts = np.asarray(track, dtype=float).reshape(-1, 2)
    if len(pts) == 1:
        return Room(pts, pts, half)
    a, b = pts[:-1], pts[1:]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    r = reach + half
    keep = (lo[:, 0] <= at[0] + r) & (hi[:, 0] >= at[0] - r) & (lo[:, 1] <= at[1] + r) & (hi[:, 1] >= at[1] - r)
    return Room(a[keep], b[keep], half)
