"""``pfp report --terrain DEM``: climb, steepest ground and time in view, per unit, over the Jacksboro DEM.

A record is written with the recorder's own writer: one unit walking
straight across the ridges on its own clock, and a threat watching it.  The
figures are checked against what is computed here independently, from the
raw DEM cells (a bilinear profile written here) and from ``pfp terrain
viewshed``'s sweep on the DEM's own grid (where the report casts exact rays
on the planner's plane).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from pfp_clients.record.mcapfile import MissionWriter, read_record
from pfp_clients.record.report import write_report

from pfp_service.core.mobility import CLASSES
from pfp_service.geo import Origin
from pfp_service.wire import keys
from tests.conftest import run_pfp
from tests.proc.test_map_cli import _one_line_exit_2
from tests.terrain_data import jacksboro, write_geographic

M = "rt"
S = 1_000_000_000
ORIGIN = Origin(lat=36.59, lon=-84.25, alt=0.0)
SPEED = 5.0
THREAT = {"position": [1000.0, 1000.0], "facing_deg": 180, "sigma_range": 2500, "sigma_lateral": 2500}


def _track() -> list[tuple[float, float]]:
    a, b = np.array([-4000.0, -2500.0]), np.array([4000.0, 1500.0])
    n = int(np.hypot(*(b - a)) / SPEED)
    return [tuple(map(float, a + (b - a) * i / n)) for i in range(n + 1)]


def _record(path: Path, origin: Origin | None) -> Path:
    with path.open("wb") as f:
        w = MissionWriter(f, M, origin, 0)
        w.put(keys.threat(M, "e1"), json.dumps(THREAT).encode(), 0)
        for i, (x, y) in enumerate(_track()):  # one report a (unit) second, sent every 10 ms
            state = {"position": [x, y], "seq": i, "t": float(i), "kind": "manned", "speed_mps": SPEED}
            w.put(keys.unit_state(M, "u1"), json.dumps(state).encode(), S + i * S // 100)
        w.finish()
    return path


def _bilinear(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    z, west, north, step = jacksboro()
    r, c = (north - lat) / step - 0.5, (lon - west) / step - 0.5
    r0, c0 = np.floor(r).astype(int), np.floor(c).astype(int)
    fr, fc = r - r0, c - c0
    zz = z.astype(float)
    return (1 - fr) * ((1 - fc) * zz[r0, c0] + fc * zz[r0, c0 + 1]) + fr * (
        (1 - fc) * zz[r0 + 1, c0] + fc * zz[r0 + 1, c0 + 1]
    )


@pytest.mark.unit
def test_the_report_measures_each_track_over_the_ground(tmp_path):
    from pfp_service.core.threat import ThreatField
    from pfp_service.core.visibility import reach_box
    from pfp_service.terrain.sight import observe
    from pfp_service.terrain.viewshed import visible

    dem = write_geographic(tmp_path / "jacksboro.tif")
    rec = read_record(_record(tmp_path / "r.mcap", ORIGIN))
    lines: list[str] = []
    written = write_report(rec, tmp_path / "out", say=lines.append, ground=(str(dem), CLASSES["foot"]))
    text = "\n".join(lines)
    assert "terrain: jacksboro.tif" in text and "climb" in text and "in view" in text

    rows = list(csv.reader((tmp_path / "out.csv").open()))
    assert rows[0][-3:] == ["climb m", "max slope deg", "in view s"]
    gj = json.loads((tmp_path / "out.geojson").read_text())
    assert gj["terrain"]["unit_class"] == "foot" and gj["terrain"]["unit_height_m"] == 1.8
    (track,) = [f for f in gj["features"] if f["properties"]["kind"] == "track"]
    props = track["properties"]
    assert props["climb m"] == f"{props['climb_m']:.1f}"
    assert tmp_path / "out.geojson" in written

    # the climb, from the raw cells: every rise along the track, sampled every 5 m
    pts = np.array(_track())
    fine = np.concatenate(
        [a + np.linspace(0, 1, 4, endpoint=False)[:, None] * (b - a) for a, b in zip(pts[:-1], pts[1:])]
    )
    ll = ORIGIN.to_geodetic_many(fine)
    z = _bilinear(ll[:, 0], ll[:, 1])
    climb = float(np.maximum(np.diff(z), 0).sum())
    assert climb > 100  # across ridges: real climbing
    assert props["climb_m"] == pytest.approx(climb, rel=0.10)
    grade = np.degrees(np.arctan(np.abs(np.diff(z)) / np.hypot(*np.diff(fine, axis=0).T)))
    # the ground's steepest slope at least the track's own steepest grade, and no cliff
    assert float(np.max(grade)) * 0.9 <= props["max_slope_deg"] < 60

    # time in view, from pfp terrain viewshed's sweep on the DEM's grid, segment by segment
    t_lat, t_lon = ORIGIN.to_geodetic(*THREAT["position"])
    sight = observe(str(dem), t_lat, t_lon, 2.0, 12_000.0, 0.0)
    seen = visible(sight.lowest_m, 1.8)
    mid = 0.5 * (pts[:-1] + pts[1:])
    x0, y0, x1, y1 = reach_box(ThreatField([_threat()], "peak").packed[0])
    near = (mid[:, 0] >= x0) & (mid[:, 0] <= x1) & (mid[:, 1] >= y0) & (mid[:, 1] <= y1)
    mll = ORIGIN.to_geodetic_many(mid)
    from rasterio.warp import transform as warp

    xs, ys = warp("EPSG:4326", sight.dem.crs, mll[:, 1], mll[:, 0])
    col, row = ~sight.dem.transform @ (np.array(xs), np.array(ys))
    in_view = near & seen[np.floor(row).astype(int), np.floor(col).astype(int)]
    want = float(in_view.sum())  # one second a segment
    got = props["in_view_s"]["e1"]
    print(
        f"in view: report {got:.0f} s, sweep {want:.0f} s of {len(mid)} s; climb {props['climb_m']:.0f} m vs {climb:.0f} m"
    )
    assert 0.1 * len(mid) < want < 0.9 * len(mid)  # partly hidden: a figure that can be wrong either way
    assert got == pytest.approx(want, rel=0.05)


def _threat():
    from pfp_service.wire import ThreatUpdate
    from pfp_service.world import translate

    return translate.threat(ThreatUpdate(**THREAT), "e1")  # type: ignore[arg-type]


@pytest.mark.proc
def test_a_record_without_origin_or_a_dem_not_under_it_is_one_line_exit_2(tmp_path):
    dem = write_geographic(tmp_path / "jacksboro.tif")
    plain = _record(tmp_path / "plain.mcap", None)
    line = _one_line_exit_2(run_pfp("report", str(plain), "--terrain", str(dem), timeout=60))
    assert line.startswith("pfp report: --terrain:") and "no origin" in line, line
    far = _record(tmp_path / "far.mcap", Origin(lat=58.41, lon=15.62, alt=0.0))
    line = _one_line_exit_2(run_pfp("report", str(far), "--terrain", str(dem), timeout=60))
    assert str(dem) in line and "does not cover" in line, line
    # a decompression bomb is refused from its header (test_light_commands measures the others' peak)
    from rasterio.transform import from_origin

    from tests.unit.test_terrain import _write

    bomb = _write(
        tmp_path / "bomb.tif", width=8_000, height=1_000, blockysize=1_000, compress="deflate",
        crs="EPSG:4326", transform=from_origin(-84.5, 36.8, 0.001, 0.001),
    )  # fmt: skip
    near = _record(tmp_path / "near.mcap", ORIGIN)
    line = _one_line_exit_2(run_pfp("report", str(near), "--terrain", str(bomb), timeout=60))
    assert str(bomb) in line and "dem_block_cells" in line, line
