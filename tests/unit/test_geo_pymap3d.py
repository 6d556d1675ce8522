"""The plane's inverse and a bearing's rotation, written out for their cost (``geo._plane``,
``geo.bearings_at``), against pymap3d's own formulas, which they replace on every tick (issue 32)."""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service import geo
from pfp_service.geo import Origin
from tests.unit.test_geo import ORIGINS


@pytest.mark.unit
@pytest.mark.parametrize("lat0", [0.0, 33.2, 59.3, -45.0, 80.0, -89.0])
@pytest.mark.parametrize("lon0", [-179.9, 18.07, 179.95])
@pytest.mark.parametrize("alt", [0.0, 1_500.0, -300.0, 90_000.0])
def test_to_geodetic_is_pymap3ds_inverse_over_the_whole_plane(lat0, lon0, alt):
    """The written-out inverse against pymap3d: a grid out to ``MAX_RANGE_M``, across the antimeridian
    and near a pole.  Each lat/lon is where pymap3d's own ``enu2geodetic`` puts the plane's point (to
    1e-9 degrees, on the plane's height to a micrometre), and pymap3d's ``geodetic2enu`` takes it back."""
    import pymap3d

    o = Origin(lat=lat0, lon=lon0, alt=alt)
    grid = np.linspace(-geo.MAX_RANGE_M, geo.MAX_RANGE_M, 17)
    xy = np.array([(x, y) for x in grid for y in grid])
    ll = o.to_geodetic_many(xy)
    e, n, up = pymap3d.geodetic2enu(ll[:, 0], ll[:, 1], alt, lat0, lon0, alt)
    assert np.max(np.abs(np.column_stack([e, n]) - xy)) < 1e-6
    lat, lon, h = pymap3d.enu2geodetic(xy[:, 0], xy[:, 1], up, lat0, lon0, alt)
    assert np.max(np.abs(lat - ll[:, 0])) < 1e-9
    assert np.max(np.abs((lon - ll[:, 1] + 180.0) % 360.0 - 180.0)) < 1e-9
    assert np.max(np.abs(h - alt)) < 1e-6
    assert np.all(np.abs(ll[:, 1]) <= 180.0)


@pytest.mark.unit
@pytest.mark.parametrize("o", ORIGINS)
def test_bearings_are_pymap3ds_rotation(o):
    """A planner vector turned into a point's own frame, written out, against pymap3d's two rotations."""
    import pymap3d

    rng = np.random.default_rng(3)
    xy = rng.uniform(-geo.MAX_RANGE_M, geo.MAX_RANGE_M, size=(300, 2))
    vec = rng.normal(size=(300, 2))
    ll = o.to_geodetic_many(xy)
    got = geo.bearings_at(o, ll[:, 0], ll[:, 1], vec)
    u, v, w = pymap3d.enu2uvw(vec[:, 0], vec[:, 1], 0.0, o.lat, o.lon)
    e, n, _up = pymap3d.uvw2enu(u, v, w, ll[:, 0], ll[:, 1])
    want = np.degrees(np.arctan2(e, n)) % 360.0
    assert np.max(np.abs((got - want + 180.0) % 360.0 - 180.0)) < 1e-9
    assert np.all((got >= 0.0) & (got < 360.0))
    assert geo.true_bearing_deg(o, tuple(xy[0]), tuple(vec[0])) == pytest.approx(float(got[0]), abs=1e-12)
