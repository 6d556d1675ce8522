"""A lead's track as a ``Polyline`` grown in place, for its followers: a point at a time, not the whole line again.

A lead's track grows a point each time its lead drives a sixteenth of the corridor, and its followers
walk it as a ``Polyline`` (``teams.follow``).  ``Polyline.extended`` concatenates each of its five arrays
afresh for every point, a cost that grows with the track (up to ``team_tracks.MAX_TRACK_POINTS``).  Here
the arrays are kept with room to spare (``Grown``) and a new point's segment, length and cumulated length
are written after the last (``polyline_kernels.extend_one``); the line handed out is a view of the first
rows, so a line handed out before is unchanged by the rows written after it.  The numbers are those of a
``Polyline`` of the whole track (``tests/unit/test_team_lines.py``).  A micro-optimisation (bench row:
BENCHMARKS.md "The judge's members", the judge).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pfp_service.core import polyline_kernels as kernels
from pfp_service.world.polyline import Point, Polyline
from pfp_service.world.team_tracks import MAX_TRACK_POINTS

__all__ = ["Grown", "grow"]

_ROOM = 64  # points a line's arrays hold at least; then twice what they hold, when full ...
# ... but no more than a track keeps (``team_tracks`` trims it past that): the arrays are then at most a
# ``Polyline`` of the longest track's, bounded by construction


class Grown:
    """A line's arrays with room to spare: its points ``pts[:n]`` and so on, and the line last handed out."""

    __slots__ = ("ab", "cum", "line", "n", "pts", "seg", "sq")

    def __init__(self, line: Polyline, room: int) -> None:
        n = len(line.pts)
        self.pts = np.empty((room, 2))
        self.ab = np.empty((room, 2))
        self.seg = np.empty(room)
        self.sq = np.empty(room)
        self.cum = np.empty(room)
        self.pts[:n], self.ab[: n - 1], self.seg[: n - 1] = line.pts, line.ab, line.seg
        self.sq[: n - 1], self.cum[:n] = line.sq, line.cum
        self.n, self.line = n, line


def grow(grown: Grown | None, line: Polyline, more: Sequence[Point]) -> tuple[Polyline, Grown | None]:
    """``line.extended(more)``, the same numbers, and the arrays it is a view of (``None``: none kept).

    Args:
        grown: the arrays kept for this track, if any: taken when they hold ``line`` (it was the last
            handed out from them), else left for new ones.
        line: the track's line so far.
        more: the points the track gained since.
    """
    m = len(line.pts)
    if not more:
        return line, grown
    if m == 0:
        return Polyline(more), None
    n = m + len(more)
    if grown is None or grown.line is not line or grown.n != m or n > len(grown.pts):
        grown = Grown(line, max(n, min(2 * n, MAX_TRACK_POINTS), _ROOM))
    for k, (x, y) in enumerate(more):
        kernels.extend_one(grown.pts, grown.ab, grown.seg, grown.sq, grown.cum, m + k, float(x), float(y))
    out = Polyline.__new__(Polyline)
    out.pts, out.ab, out.seg = grown.pts[:n], grown.ab[: n - 1], grown.seg[: n - 1]
    out.sq, out.cum = grown.sq[: n - 1], grown.cum[:n]
    grown.n, grown.line = n, out
    return out, grown
