"""A zone set's bins (``core.zone_bins``): a point's zones within a reach, the same answer as every zone's box.

``ZoneSet.signed_distance`` with a finite reach and ``BINNED_FROM`` zones or
more measures each point only against the zones binned in the cells its reach
meets; ``zone_kernels.signed_many`` looks at every zone.  They must agree to
the bit, on random sets, on points on the zones' edges and corners, at
non-finite points, and on a real terrain's slope barriers.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pfp_service.core import zone_kernels
from pfp_service.core.zone_bins import BINNED_FROM, bins_of
from pfp_service.core.zones import TOUCH_M, Zone, ZoneSet

pytestmark = pytest.mark.unit

REACHES = [0.0, TOUCH_M, 0.5, 3.0, 40.0, 1e4]


def _every_zone(zs: ZoneSet, pts: np.ndarray, reach: float) -> np.ndarray:
    out = np.full(len(pts), math.inf)
    zone_kernels.signed_many(zs.edges, zs.offsets, zs.circles, zs.boxes, pts, out, float(reach))
    return out


def _random_set(rng: np.random.Generator) -> ZoneSet:
    zones = []
    for k in range(int(rng.integers(BINNED_FROM, 160))):
        x, y = rng.uniform(-500, 500, 2)
        w, h = rng.uniform(0.05, 80.0, 2) * (20.0 if k % 17 == 0 else 1.0)  # a few zones far larger
        if k % 4 == 0:
            zones.append(Zone.circle(f"c{k}", (float(x), float(y)), float(w)))
        elif k % 4 == 1:  # a star: concave
            a = np.sort(rng.uniform(0, 2 * math.pi, int(rng.integers(3, 12))))
            r = rng.uniform(0.2, 1.0, len(a)) * w
            ring = [
                (float(x + ri * math.cos(ai)), float(y + ri * math.sin(ai)))
                for ai, ri in zip(a, r, strict=True)
            ]
            try:
                zones.append(Zone.polygon(f"s{k}", ring))
            except Exception:  # a degenerate star: refused as the wire would refuse it
                continue
        else:
            ring = [(x, y), (x + w, y), (x + w, y + h), (x, y + h)]
            zones.append(Zone.polygon(f"p{k}", [(float(a), float(b)) for a, b in ring]))
    return ZoneSet(zones)


def _points(zs: ZoneSet, rng: np.random.Generator, n: int) -> np.ndarray:
    """Anywhere, near the zones' vertices and on them exactly, and on their boxes' sides."""
    anywhere = rng.uniform(-700, 700, (n, 2))
    verts = zs.edges[:, :2]
    near = verts[rng.integers(0, len(verts), n)] + rng.normal(0.0, 0.3, (n, 2))
    on = verts[rng.integers(0, len(verts), n // 4)]
    b = zs.boxes[rng.integers(0, len(zs.boxes), n // 4)]
    sides = np.column_stack([b[:, 0], b[:, 1] + rng.uniform(0, 1, len(b)) * (b[:, 3] - b[:, 1])])
    return np.ascontiguousarray(np.vstack([anywhere, near, on, sides]))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_binned_is_every_zone_to_the_bit_on_random_sets(seed: int) -> None:
    rng = np.random.default_rng(seed)
    zs = _random_set(rng)
    if len(zs) < BINNED_FROM:
        return
    pts = _points(zs, rng, 600)
    for reach in REACHES:
        got = zs.signed_distance(pts, reach)
        assert zs._bins is not None and zs._bins[0] is not None  # the bins answered, not every zone's box
        want = _every_zone(zs, pts, reach)
        assert np.array_equal(got, want), (seed, reach, np.flatnonzero(got != want)[:5])
        assert np.array_equal(zs.contains(pts, reach), want <= max(TOUCH_M, reach))


def test_points_off_the_grid_and_not_finite_are_answered_as_before() -> None:
    zs = _random_set(np.random.default_rng(7))
    assert len(zs) >= BINNED_FROM
    pts = np.array(
        [
            [math.nan, 0.0],
            [0.0, math.inf],
            [-math.inf, 3.0],
            [1e300, -1e300],
            [5e3, 5e3],
            [-9e5, 0.0],
            [2e15, 0.0],
        ]
    )
    for reach in [*REACHES, 1e300, math.nan]:
        got = zs.signed_distance(pts, reach)
        assert np.array_equal(got, _every_zone(zs, pts, reach), equal_nan=True), reach


def test_a_set_too_large_to_bin_measures_every_zone(monkeypatch: pytest.MonkeyPatch) -> None:
    from pfp_service.core import zone_bins

    rng = np.random.default_rng(11)
    monkeypatch.setattr(zone_bins, "MAX_ENTRIES", 10)
    zs = _random_set(rng)
    pts = _points(zs, rng, 200)
    assert np.array_equal(zs.signed_distance(pts, 3.0), _every_zone(zs, pts, 3.0))
    assert zs._bins == (None,)


def test_the_bins_hold_each_zone_in_every_cell_its_box_meets() -> None:
    boxes = np.array([[0.0, 0.0, 10.0, 10.0], [95.0, 95.0, 100.0, 100.0], [-50.0, 40.0, 150.0, 41.0]])
    b = bins_of(boxes)
    assert b is not None
    for z, (x0, y0, x1, y1) in enumerate(boxes):
        for x in np.linspace(x0, x1, 9):
            for y in np.linspace(y0, y1, 9):
                i = min(int((x - b.x0) // b.cell), b.nx - 1)
                j = min(int((y - b.y0) // b.cell), b.ny - 1)
                c = j * b.nx + i
                assert z in b.ids[b.starts[c] : b.starts[c + 1]], (z, x, y)


def test_a_real_terrains_slope_barriers_binned_are_every_zone() -> None:
    from matplotlib import cbook

    from pfp_service.terrain.barriers import barrier_zones
    from pfp_service.terrain.grid import TerrainGrid

    d: Any = cbook.get_sample_data("jacksboro_fault_dem.npz")  # an NpzFile; its stubs say IO too
    z = np.asarray(d["elevation"], dtype=float)
    grid = TerrainGrid(0.0, 0.0, 80.0, z)  # about the DEM's 74 x 93 m cells: slopes as steep
    zs = ZoneSet(barrier_zones(grid, 12.0))
    assert len(zs) >= 4 * BINNED_FROM, len(zs)
    rng = np.random.default_rng(32)
    pts = np.vstack(
        [
            rng.uniform(0.0, 80.0 * np.array(z.shape[::-1]), (4000, 2)),
            _points(zs, rng, 2000),
        ]
    )
    for reach in (TOUCH_M, 2.0, 30.0):
        assert np.array_equal(zs.signed_distance(pts, reach), _every_zone(zs, pts, reach)), reach


def test_the_warm_up_loads_the_binned_kernel_with_the_types_a_real_set_asks() -> None:
    from pfp_service.core import zone_bins
    from pfp_service.node import warmup

    warmup._binned()
    loaded = set(zone_bins._signed_binned.signatures)
    assert loaded
    zs = _random_set(np.random.default_rng(3))
    zs.contains(_points(zs, np.random.default_rng(3), 50), 2.5)
    zs.signed_distance(np.zeros((4, 2)), TOUCH_M)
    assert set(zone_bins._signed_binned.signatures) == loaded  # nothing compiled past the warm-up
