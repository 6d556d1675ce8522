"""A polyline as arrays (``Polyline``), made once and walked many times, and its one-shot helpers.

The arithmetic of ``core.polyline_kernels`` (projection, a point along it,
shared segments) on a line's points, segments, squared lengths and cumulated
length; the teams' roles (``teams``) and the team book walk a lead's track
and a main element's route with it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pfp_service.core import polyline_kernels as kernels

__all__ = ["Point", "Polyline", "dist", "length", "point_at", "project"]

Point = tuple[float, float]


def dist(a: Point, b: Point) -> float:
    """The distance between two points, metres."""
    return math.hypot(b[0] - a[0], b[1] - a[1])


def _squares(seg: np.ndarray) -> np.ndarray:
    """Each segment's squared length, 1 where it is 0 (a segment under 1e-154 m squares to 0): a divisor."""
    sq = seg * seg
    return np.where(sq > 0.0, sq, 1.0)


class Polyline:
    """A polyline as arrays, its segments' lengths and cumulated length: made once, walked many times."""

    __slots__ = ("ab", "cum", "pts", "seg", "sq")

    def __init__(self, line: Sequence[Point] | np.ndarray) -> None:
        self.pts = np.asarray(line, dtype=float).reshape(-1, 2)
        self.ab = np.diff(self.pts, axis=0)  # each segment, start to end: made once for every walk
        self.seg = np.hypot(self.ab[:, 0], self.ab[:, 1]) if len(self.pts) > 1 else np.zeros(0)
        self.sq = _squares(self.seg)
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg)])

    def __len__(self) -> int:
        return len(self.pts)

    def extended(self, more: Sequence[Point]) -> Polyline:
        """This line with ``more`` points after its last: the very numbers a line of them all has,
        at the cost of the new points (a lead's track grows by a point at a time)."""
        if not more:
            return self
        if len(self.pts) == 0:
            return Polyline(more)
        out = Polyline.__new__(Polyline)
        add = np.asarray(more, dtype=float).reshape(-1, 2)
        out.pts = np.concatenate([self.pts, add])
        ab = np.diff(out.pts[len(self.pts) - 1 :], axis=0)
        seg = np.hypot(ab[:, 0], ab[:, 1])
        out.ab = np.concatenate([self.ab, ab])
        out.seg = np.concatenate([self.seg, seg])
        out.sq = np.concatenate([self.sq, _squares(seg)])
        # cumulated from the last total on, one addition at a time: as the whole line's cumsum adds
        out.cum = np.concatenate([self.cum, np.cumsum(np.concatenate([self.cum[-1:], seg]))[1:]])
        return out

    @property
    def length(self) -> float:
        return float(self.cum[-1])

    def shared(self, at: Point, to: Point, half: float) -> bool:
        """Whether ``at`` and ``to`` both lie within ``half`` of one segment (of the one point, for a line of one)."""
        pts = self.pts
        if len(pts) == 1:
            c = (float(pts[0, 0]), float(pts[0, 1]))
            return dist(at, c) <= half and dist(to, c) <= half
        return bool(kernels.shared(pts, self.ab, self.sq, at[0], at[1], to[0], to[1], half))

    def project(self, at: Point) -> tuple[float, float]:
        pts = self.pts
        if len(pts) == 0:
            return 0.0, math.inf
        if len(pts) == 1:
            return 0.0, dist(at, (float(pts[0, 0]), float(pts[0, 1])))
        s, off = kernels.project(pts, self.ab, self.sq, self.seg, self.cum, at[0], at[1])
        return float(s), float(off)

    def point_at(self, s: float) -> Point:
        pts, cum = self.pts, self.cum
        if len(pts) == 0:
            raise ValueError("point_at: an empty line")
        if s <= 0.0 or len(pts) == 1:
            return float(pts[0, 0]), float(pts[0, 1])
        if s >= cum[-1]:
            return float(pts[-1, 0]), float(pts[-1, 1])
        i = int(np.searchsorted(cum, s, side="right")) - 1  # the segment s ends on: cum[i] <= s < cum[i + 1]
        f = (s - cum[i]) / (cum[i + 1] - cum[i])
        return float(pts[i, 0] + (pts[i + 1, 0] - pts[i, 0]) * f), float(
            pts[i, 1] + (pts[i + 1, 1] - pts[i, 1]) * f
        )


def project(at: Point, line: Sequence[Point]) -> tuple[float, float]:
    """``(s, d)``: how far along ``line`` (a polyline, metres from its start) ``at``'s nearest point lies, and how far off it is.

    One point is a line of no length; no point puts ``at`` infinitely far off.
    """
    return Polyline(line).project(at)


def point_at(line: Sequence[Point], s: float) -> Point:
    """The point ``s`` metres along ``line`` from its start (its ends beyond them)."""
    return Polyline(line).point_at(s)


def length(line: Sequence[Point]) -> float:
    """The length of a polyline, metres."""
    return Polyline(line).length
