"""A ray's first clear point, found with the zones measured only where a ray is still undecided, is the one
every point's ``inside`` gives (``Cores.first_clear``, which ``Escape.leave_core`` walks its 72 rays with)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import Threat, ThreatField
from pfp_service.core.cores import Cores
from pfp_service.core.zones import Zone, ZoneSet

pytestmark = pytest.mark.unit


def _field(seed: int, zones: int) -> ThreatField:
    rng = np.random.default_rng(seed)
    threats = []
    for k in range(12):
        x, y = rng.uniform(-300.0, 300.0, 2)
        sr, sl = rng.uniform(10.0, 60.0, 2)
        threats.append(
            Threat.from_facing((float(x), float(y)), float(rng.uniform(0, 360)), sr, sl, 1.0, 1.0, f"t{k}")
        )
    made = []
    for k in range(zones):  # boxes and circles scattered over the rays, some overlapping the cores
        cx, cy = rng.uniform(-400.0, 400.0, 2)
        if k % 3 == 0:
            made.append(
                Zone(id=f"c{k}", centre=(float(cx), float(cy)), radius_m=float(rng.uniform(5.0, 40.0)))
            )
        else:
            w, h = rng.uniform(5.0, 80.0, 2)
            shell = ((cx - w, cy - h), (cx + w, cy - h), (cx + w, cy + h), (cx - w, cy + h))
            made.append(Zone(id=f"z{k}", shell=tuple((float(a), float(b)) for a, b in shell)))
    return ThreatField(threats).with_zones(ZoneSet(made))


def _rays(x: float, y: float, reach: float, n: int, m: int = 72) -> np.ndarray:
    angles = np.linspace(0.0, 2.0 * math.pi, m, endpoint=False)
    d = np.arange(1, n + 1) * (reach / n)
    return np.stack([x + np.sin(angles)[:, None] * d, y + np.cos(angles)[:, None] * d], axis=-1)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("zones", [0, 5, 60])
@pytest.mark.parametrize("fraction", [None, 0.5])
def test_the_first_clear_point_of_each_ray_is_the_one_every_point_s_inside_gives(seed, zones, fraction):
    field = _field(seed, zones)
    cores = Cores.of(field) if fraction is None else Cores.of(field, fraction)
    rng = np.random.default_rng(100 + seed)
    for x, y in rng.uniform(-250.0, 250.0, (3, 2)):
        for n, chunk in ((300, 64), (37, 5), (1, 64)):
            rays = _rays(float(x), float(y), 500.0, n)
            blocked = cores.inside(rays.reshape(-1, 2)).reshape(rays.shape[0], n)
            want = np.where(blocked.all(axis=1), n, np.argmin(blocked, axis=1))
            assert np.array_equal(cores.first_clear(rays, chunk), want)


def test_a_ray_blocked_all_along_is_n_and_one_clear_at_once_is_zero():
    wall = Zone(id="wall", shell=((-1000.0, -1000.0), (1000.0, -1000.0), (1000.0, 1000.0), (-1000.0, 1000.0)))
    cores = Cores.of(ThreatField([]).with_zones(ZoneSet([wall])))
    assert cores.first_clear(_rays(0.0, 0.0, 500.0, 50)).tolist() == [50] * 72
    open_ground = Cores.of(
        ThreatField([]).with_zones(ZoneSet([Zone(id="far", centre=(5000.0, 0.0), radius_m=1.0)]))
    )
    assert open_ground.first_clear(_rays(0.0, 0.0, 500.0, 50)).tolist() == [0] * 72
