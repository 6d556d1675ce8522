"""The cleared corridor's closed form (``world.corridor``) against GEOS and against the distances themselves.

The capsules' union is the track buffered exactly; GEOS's buffer of the same
segments is inscribed in it (its arcs are chords) and, widened by the chords'
sag, circumscribes it.  So the part of a step kept in the capsules lies between
the parts kept in those two polygons, and every point of it is within the
half-width of the track.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
import shapely

from pfp_service.world import corridor
from pfp_service.world.teams import Polyline

pytestmark = pytest.mark.unit

_QUAD = 16  # GEOS's quarter-circle segments for the reference polygons


def _geos_kept(pts: np.ndarray, half: float, at: tuple[float, float], to: tuple[float, float]) -> float:
    """How much of the step from ``at`` stays in ``room`` from its start, by GEOS (the code this replaced)."""
    room = (
        shapely.Point(pts[0]).buffer(half, quad_segs=_QUAD)
        if len(pts) == 1
        else shapely.buffer(
            shapely.MultiLineString([[tuple(a), tuple(b)] for a, b in zip(pts[:-1], pts[1:])]),
            half,
            quad_segs=_QUAD,
        )
    )
    far = math.dist(at, to)
    if far <= 0.0:
        return 1.0 if room.covers(shapely.Point(at)) else 0.0
    step = shapely.LineString([at, to])
    if room.covers(step):
        return 1.0
    for part in shapely.get_parts(step.intersection(room)):
        if isinstance(part, shapely.LineString) and part.distance(shapely.Point(at)) < 1e-9:
            return min(1.0, max(math.dist(at, c) for c in part.coords) / far)
    return 0.0


def _off(pts: np.ndarray, p: tuple[float, float]) -> float:
    """How far ``p`` is from the polyline ``pts``: every segment's nearest point, by NumPy."""
    if len(pts) == 1:
        return math.dist(p, pts[0])
    a, ab = pts[:-1], np.diff(pts, axis=0)
    sq = np.where((ab * ab).sum(axis=1) > 0.0, (ab * ab).sum(axis=1), 1.0)
    t = np.clip(((p - a) * ab).sum(axis=1) / sq, 0.0, 1.0)
    return float(np.hypot(*(a + ab * t[:, None] - p).T).min())


@pytest.mark.parametrize("seed", range(60))
def test_a_projection_is_numpys_over_every_segment(seed: int) -> None:
    pts, _half, at, to = _case(seed)
    line = Polyline(pts)
    for p in (at, to):
        assert line.project(p)[1] == pytest.approx(_off(pts, p), abs=1e-9), f"seed {seed}"
        assert line.shared(at, to, _half) == any(
            _off(pts[k : k + 2], at) <= _half and _off(pts[k : k + 2], to) <= _half
            for k in range(max(len(pts) - 1, 1))
        ), f"seed {seed}"


def _case(seed: int) -> tuple[np.ndarray, float, tuple[float, float], tuple[float, float]]:
    rng = random.Random(seed)
    n = rng.randint(1, 12)
    pts = [(0.0, 0.0)]
    for _ in range(n - 1):
        last = pts[-1]
        pts.append((last[0] + rng.uniform(-3.0, 12.0), last[1] + rng.uniform(-8.0, 8.0)))
        if rng.random() < 0.1:
            pts.append(pts[-1])
    half = rng.uniform(1.0, 6.0)
    line = Polyline(pts)
    s = rng.uniform(0.0, line.length)
    base = line.point_at(s)
    at = (base[0] + rng.uniform(-half, half), base[1] + rng.uniform(-half, half))
    ang, far = rng.uniform(0.0, 2 * math.pi), rng.choice([0.0, rng.uniform(0.5, 30.0)])
    return np.asarray(pts, dtype=float), half, at, (at[0] + far * math.cos(ang), at[1] + far * math.sin(ang))


@pytest.mark.parametrize("seed", range(120))
def test_the_part_kept_lies_between_geos_inner_and_outer_buffers(seed: int) -> None:
    pts, half, at, to = _case(seed)
    got = corridor.near(pts, half, at, max(math.dist(at, to), 1.0)).kept(at, to)
    sag = 1.0 / math.cos(math.pi / (4 * _QUAD))  # a chord's polygon widened by this holds the arc
    inner, outer = _geos_kept(pts, half, at, to), _geos_kept(pts, half * sag, at, to)
    assert inner - 1e-9 <= got <= outer + 1e-9, f"seed {seed}: {inner} <= {got} <= {outer}"


@pytest.mark.parametrize("seed", range(120))
def test_every_point_kept_is_within_the_half_width_and_the_next_is_not(seed: int) -> None:
    pts, half, at, to = _case(seed)
    got = corridor.near(pts, half, at, max(math.dist(at, to), 1.0)).kept(at, to)
    far = math.dist(at, to)

    def off(t: float) -> float:
        return _off(pts, (at[0] + (to[0] - at[0]) * t, at[1] + (to[1] - at[1]) * t))

    if got > 0.0:
        assert all(off(got * k / 64) <= half + 1e-7 for k in range(65)), f"seed {seed}"
    if got < 1.0 and far > 0.0:
        assert off(min(1.0, got + 1e-3 / far)) > half - 1e-3 or (got == 0.0 and off(0.0) > half - 1e-6), (
            f"seed {seed}"
        )


def test_a_room_of_nothing_keeps_nothing_and_a_point_is_a_disc() -> None:
    empty = corridor.Room(np.zeros((0, 2)), np.zeros((0, 2)), 2.0)
    assert empty.kept((0.0, 0.0), (1.0, 0.0)) == 0.0
    disc = corridor.near([(0.0, 0.0)], 2.0, (0.0, 0.0), 5.0)
    assert disc.kept((0.0, 0.0), (4.0, 0.0)) == pytest.approx(0.5)
    assert disc.kept((1.0, 0.0), (1.0, 0.0)) == 1.0 and disc.kept((3.0, 0.0), (3.0, 0.0)) == 0.0
