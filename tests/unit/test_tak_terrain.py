"""``pfp tak --terrain DEM``: routes carry the DEM's ground as each waypoint's ``hae``.

The bridge's state machine is driven directly (sans-I/O) with the Jacksboro DEM
read by the client's loader; the heights it sends are checked against a
bilinear interpolation of the DEM's cells written here, from the raw array.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from pfp_clients.ground import load_ground
from pfp_clients.tak.state import BridgeSettings, BridgeState

from pfp_service.geo import Origin
from tests.conftest import run_pfp
from tests.proc.test_map_cli import _one_line_exit_2
from tests.terrain_data import jacksboro, write_geographic, write_utm
from tests.zenoh_util import free_port

T0 = 1_796_000_000.0


def _bilinear(lat: float, lon: float) -> float:
    """The DEM's height at ``(lat, lon)``: cell values at cell centres, interpolated between the four round."""
    z, west, north, step = jacksboro()
    r, c = (north - lat) / step - 0.5, (lon - west) / step - 0.5
    r0, c0 = int(np.floor(r)), int(np.floor(c))
    fr, fc = r - r0, c - c0
    q = z[r0 : r0 + 2, c0 : c0 + 2].astype(float)
    return float((1 - fr) * ((1 - fc) * q[0, 0] + fc * q[0, 1]) + fr * ((1 - fc) * q[1, 0] + fc * q[1, 1]))


@pytest.mark.unit
@pytest.mark.parametrize("crs", ["geographic", "utm"])
def test_a_routes_waypoints_carry_the_dems_ground_as_hae(tmp_path, crs):
    dem = write_geographic(tmp_path / "jacksboro.tif")
    if crs == "utm":
        dem = write_utm(dem, tmp_path / "jacksboro-utm.tif")
    ground = load_ground(str(dem))
    origin = Origin(lat=36.59, lon=-84.25, alt=123.0)
    s = BridgeState(BridgeSettings(mission="m", origin=origin, ground=ground.elevation, route_points=50))
    # across the fault's ridges, and on to 40 km east: off the DEM
    path = [(float(x), 0.3 * float(x)) for x in range(-6000, 6001, 500)] + [(40_000.0, 0.0)]
    (route,) = s.on_route("u1", path, "reached", 13_000.0, T0).cot
    root = ET.fromstring(route)
    points = [tuple(map(float, lk.get("point").split(","))) for lk in root.findall("detail/link")]
    assert len(points) == len(path)
    on = points[:-1]
    want = [_bilinear(lat, lon) for lat, lon, _ in on]
    got = [h for _, _, h in on]
    # the UTM copy was resampled once (bilinear) by GDAL: its ground is the DEM's, smoothed
    tol = 1e-6 if crs == "geographic" else 25.0
    assert got == pytest.approx(want, abs=tol)
    assert max(want) - min(want) > 100  # real ground: ridges and valleys, not one height
    assert points[-1][2] == 123.0  # off the DEM: the origin's altitude, as without --terrain
    assert float(root.find("point").get("hae")) == pytest.approx(want[0], abs=tol)
    if crs == "utm":  # and mostly much closer than the bound
        assert float(np.median(np.abs(np.subtract(got, want)))) < 5.0


@pytest.mark.unit
def test_without_terrain_every_waypoint_is_at_the_origins_altitude():
    s = BridgeState(BridgeSettings(mission="m", origin=Origin(lat=36.59, lon=-84.25, alt=123.0)))
    (route,) = s.on_route("u1", [(0.0, 0.0), (100.0, 0.0), (200.0, 50.0)], "reached", 210.0, T0).cot
    heights = {lk.get("point").split(",")[2] for lk in ET.fromstring(route).findall("detail/link")}
    assert heights == {"123.0"}


@pytest.mark.proc
def test_a_bad_dem_is_one_line_exit_2(tmp_path):
    pytest.importorskip("pytak")
    bad = tmp_path / "notes.tif"
    bad.write_text("no raster here\n")
    r = run_pfp(
        "tak", "--origin", "36.59,-84.25", "--terrain", str(bad), "--connect", f"tcp/127.0.0.1:{free_port()}",
        timeout=60,
    )  # fmt: skip
    line = _one_line_exit_2(r)
    assert str(bad) in line and "is not a DEM" in line, line
