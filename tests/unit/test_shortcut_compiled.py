"""A plan's shortcut over a masked field with keep-out zones runs compiled, and keeps what the numpy loop keeps.

``polylines._chunked_kept`` (a field with no cull index, such as a terrain
plan's few threats) must pick, from every kept point, the very candidate the
numpy loop of ``_shortcut_kept_numpy`` picks: the same chunks, interval
counts, cost test and clearance (zones, then cores).  ``ZoneSet.clearance``
skips zones whose box is farther than the least distance so far; it must
give the same figure as measuring every zone.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from pfp_service.core import Threat, ThreatField
from pfp_service.core.cores import SEARCH_FRACTION, Cores
from pfp_service.core.metrics import LAMBDA
from pfp_service.core.mobility import CLASSES
from pfp_service.core.polylines import _shortcut_kept_numpy
from pfp_service.core.zones import Zone, ZoneSet
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.threat_sight import TerrainSight

pytestmark = pytest.mark.unit

ZONES = ZoneSet(
    [
        Zone(id="ridge", shell=((-900.0, -200.0), (-700.0, -200.0), (-700.0, 900.0), (-900.0, 900.0))),
        Zone(id="gully", shell=((400.0, -900.0), (1200.0, -700.0), (1100.0, -500.0), (350.0, -750.0))),
        Zone.circle("crater", (300.0, 600.0), 180.0),
    ]
)


def _field() -> ThreatField:
    """Two threats over walls every 400 m (each sees only strips of ground), with the zones in force."""
    xs = np.arange(-2000.0, 2020.0, 40.0)
    gx, _ = np.meshgrid(xs, xs)
    grid = TerrainGrid(-2000.0, -2000.0, 40.0, np.where(np.mod(gx, 400.0) < 80.0, 40.0, 0.0))
    threats = [
        Threat.from_facing((-1900.0, 0.0), 90.0, 1500.0, 1200.0, 0.0, 1.0, "tower", observer_height_m=60.0),
        Threat.from_facing((600.0, 1500.0), 180.0, 500.0, 400.0, 1.0, 1.0, "post"),
    ]
    return ThreatField(threats, zones=ZONES, sight=TerrainSight(grid, CLASSES["foot"].height_m))


def _walk(rng: np.random.Generator, n: int) -> np.ndarray:
    """A wandering polyline of ``n`` points, steps of 40 to 120 m, round the middle of the field."""
    heading = rng.uniform(0.0, 2.0 * math.pi) + np.cumsum(rng.normal(0.0, 0.35, n - 1))
    steps = rng.uniform(40.0, 120.0, n - 1)[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    start = rng.uniform(-1200.0, 1200.0, 2)
    return np.concatenate([[start], start + np.cumsum(steps, axis=0)])


@pytest.mark.parametrize("seed", range(12))
def test_the_compiled_shortcut_keeps_what_the_numpy_loop_keeps(seed: int) -> None:
    field = _field()
    cores = Cores.of(field, SEARCH_FRACTION)
    rng = np.random.default_rng(seed)
    kinds = set()
    for _ in range(6):
        pts = _walk(rng, int(rng.integers(20, 90)))
        for lam in (LAMBDA, 4.0 * LAMBDA, 0.0):
            slow = _shortcut_kept_numpy(field, pts, lam, cores, compiled=False)
            fast = _shortcut_kept_numpy(field, pts, lam, cores)
            assert fast.tolist() == slow.tolist(), f"seed {seed}, lambda {lam}"
            kinds.add(len(fast) < len(pts) // 3)
    assert kinds == {True, False}  # some walks shortcut far, some are held back (cost, zones or cores)


def test_without_cores_the_compiled_shortcut_still_keeps_what_the_numpy_loop_keeps() -> None:
    field = _field()
    rng = np.random.default_rng(5)
    for _ in range(10):
        pts = _walk(rng, 40)
        assert (
            _shortcut_kept_numpy(field, pts, LAMBDA, None).tolist()
            == _shortcut_kept_numpy(field, pts, LAMBDA, None, compiled=False).tolist()
        )


@pytest.mark.parametrize("seed", range(6))
def test_clearance_is_the_least_over_every_zone(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(20):
        pts = _walk(rng, int(rng.integers(2, 40)))
        least = float(ZONES.signed_distance(pts).min())
        if least > 0.0 and len(pts) > 1:
            line = shapely.LineString(pts)
            least = min(least, min(float(z.geometry.distance(line)) for z in ZONES))
            if ZONES.first_hit(pts)[0] >= 0:
                least = min(least, 0.0)
        assert ZONES.clearance(pts) == least
