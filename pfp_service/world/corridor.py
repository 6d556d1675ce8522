"""The ground a lead has cleared near a follower, as capsules: how much of a straight step stays on it.

A lead's track buffered by half the corridor is the union of one capsule
(a segment's points within ``half``) per segment.  A step's line meets a
capsule, which is convex, in one interval of the step; the part of the step
kept from its start is the run of those intervals that covers its start.
Exact, in closed form over the segments near the step (``core.polyline_kernels.kept``): no
polygon is built (a buffer's polygon is inscribed in the capsules, its arcs
chords, so the two differ at the corridor's rounded edges by a fraction of a
percent of its width, less than the margin ``teams.follow`` keeps inside it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pfp_service.core import polyline_kernels as kernels

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
        dx, dy = to[0] - at[0], to[1] - at[1]
        return float(kernels.kept(self.a, self.b, self.half, at[0], at[1], dx, dy, _T_EPS))


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
    keep = (
        (lo[:, 0] <= at[0] + r) & (hi[:, 0] >= at[0] - r) & (lo[:, 1] <= at[1] + r) & (hi[:, 1] >= at[1] - r)
    )
    return Room(a[keep], b[keep], half)
