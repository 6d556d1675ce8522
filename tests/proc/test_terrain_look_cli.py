"""``pfp plan --terrain`` where people look, run as a user runs it: the plot's ground and GeoJSON heights."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests import terrain_data
from tests.conftest import run_pfp

pytestmark = pytest.mark.proc

SCENARIO = """\
name: jacksboro
{head}
unit: {{class: foot}}
start: [-3000, -3000]
goal: [3000, 3000]
threats:
  - {{id: t1, position: [0, 500], facing_deg: 200, sigma_range: 800, sigma_lateral: 600, skew: 1}}
  - {{id: t2, position: [1500, -1000], facing_deg: 300, sigma_range: 700, sigma_lateral: 500, skew: 1}}
"""


@pytest.fixture(scope="module")
def ground(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("look")
    terrain_data.write_geographic(d / "jacksboro.tif")
    (d / "with.yaml").write_text(SCENARIO.format(head="terrain: jacksboro.tif"))
    (d / "blind.yaml").write_text(SCENARIO.format(head=""))
    return d


def _grey_share(png: Path) -> float:
    """The share of the image's pixels in mid-tone greys (r = g = b, neither white nor black): hillshade."""
    from matplotlib import image

    rgb = image.imread(png)[..., :3]
    grey = (np.ptp(rgb, axis=-1) < 0.03) & (rgb.mean(axis=-1) > 0.15) & (rgb.mean(axis=-1) < 0.85)
    return float(grey.mean())


def test_the_plot_draws_the_ground_and_the_blind_plot_does_not(ground: Path) -> None:
    got = run_pfp("plan", str(ground / "with.yaml"), "--plot", str(ground / "with.png"))
    assert got.returncode == 0, got.stderr
    assert "Traceback" not in got.stderr and f"plot written to {ground / 'with.png'}" in got.stdout
    blind = run_pfp("plan", str(ground / "blind.yaml"), "--plot", str(ground / "blind.png"))
    assert blind.returncode == 0, blind.stderr
    with_ground, without = _grey_share(ground / "with.png"), _grey_share(ground / "blind.png")
    # the hillshade fills most of the axes; the blind plot's greys are text and ticks
    assert with_ground > 0.25 and without < 0.05, (with_ground, without)


def test_geojson_over_terrain_carries_the_ground_height(ground: Path) -> None:
    from pfp_service.scenario import load_scenario
    from pfp_service.terrain.planning import prepare

    out = ground / "with.geojson"
    got = run_pfp("plan", str(ground / "with.yaml"), "--geojson", str(out), "--json")
    assert got.returncode == 0, got.stderr
    result = json.loads(got.stdout)
    features = json.loads(out.read_text())["features"]
    (line,) = [f for f in features if f["properties"]["kind"] == "path"]
    coords = np.array(line["geometry"]["coordinates"])
    assert coords.shape == (len(result["path"]), 3)
    # the heights are the ones the plan reports, sampled on the plane the plan was made on
    assert np.allclose(coords[:, 2], result["path_elevation_m"], atol=0.005)
    sc = load_scenario(ground / "with.yaml")
    g = prepare(
        str(ground / "jacksboro.tif"), None, [sc.start, sc.goal, *(s.threat.xi for s in sc.schedule())], None,
        sc.unit.mobility(),
    )  # fmt: skip
    path = np.array(result["path"])
    assert np.allclose(coords[:, 2], g.grid.elevation(path[:, 0], path[:, 1]), atol=0.005)
    # and against the DEM itself, bilinear at each point's lon/lat, read here with no pfp code
    z, west, north, step = terrain_data.jacksboro()
    col = (coords[:, 0] - west) / step - 0.5
    row = (north - coords[:, 1]) / step - 0.5
    i, k = np.floor(col).astype(int), np.floor(row).astype(int)
    tc, tr = col - i, row - k
    zf = z.astype(float)
    direct = (1 - tr) * ((1 - tc) * zf[k, i] + tc * zf[k, i + 1]) + tr * (
        (1 - tc) * zf[k + 1, i] + tc * zf[k + 1, i + 1]
    )
    # the plane is the DEM resampled once at its own resolution, so a point is interpolated twice:
    # close to the direct sample, and never outside the heights of the DEM's posts a cell around it
    diff = np.abs(coords[:, 2] - direct)
    assert np.median(diff) < 1.0, np.median(diff)
    around = np.stack([zf[k + a, i + b] for a in (-1, 0, 1, 2) for b in (-1, 0, 1, 2)])
    assert np.all((coords[:, 2] >= around.min(axis=0) - 0.01) & (coords[:, 2] <= around.max(axis=0) + 0.01))
    for kind in ("start", "goal", "threat"):
        for f in features:
            if f["properties"]["kind"] == kind:
                assert len(f["geometry"]["coordinates"]) == 3, f


def test_geojson_without_terrain_is_unchanged(ground: Path) -> None:
    # the same scenario, placed where the terrain run places it, without the ground
    centre = "origin: {lat: 36.5895, lon: -84.246}"
    (ground / "blind-geo.yaml").write_text(SCENARIO.format(head=centre))
    out = ground / "blind.geojson"
    got = run_pfp("plan", str(ground / "blind-geo.yaml"), "--geojson", str(out))
    assert got.returncode == 0, got.stderr
    for f in json.loads(out.read_text())["features"]:
        g = f["geometry"]
        flat = [g["coordinates"]] if g["type"] == "Point" else g["coordinates"]
        if g["type"] == "Polygon":
            flat = [p for ring in flat for p in ring]
        assert all(len(p) == 2 for p in flat), f


DOC = Path(__file__).resolve().parents[2] / "docs" / "terrain.md"


def _fenced(lang: str, first: str) -> str:
    """The docs' ```lang block whose first line starts with ``first``."""
    import re

    for m in re.finditer(rf"^```{lang}\n(.*?)^```$", DOC.read_text(), re.M | re.S):
        if m[1].startswith(first):
            return m[1]
    raise AssertionError(f"docs/terrain.md has no ```{lang} block starting {first!r}")


def test_the_docs_example_writes_the_fixture_dem_and_prints_what_the_docs_show(tmp_path: Path) -> None:
    import shutil
    import subprocess
    import sys

    import rasterio

    (tmp_path / "jacksboro_dem.py").write_text(_fenced("python", "# jacksboro_dem.py"))
    subprocess.run(
        [sys.executable, "jacksboro_dem.py", "jacksboro.tif"], cwd=tmp_path, check=True, timeout=120
    )
    fixture = terrain_data.write_geographic(tmp_path / "fixture.tif")
    with rasterio.open(tmp_path / "jacksboro.tif") as a, rasterio.open(fixture) as b:
        assert a.crs == b.crs and a.transform == b.transform and a.nodata == b.nodata
        assert np.array_equal(a.read(1), b.read(1))
    (tmp_path / "examples").mkdir()
    root = DOC.parent.parent
    shutil.copy(root / "examples" / "terrain-jacksboro.yaml", tmp_path / "examples")
    got = run_pfp(
        "plan", "examples/terrain-jacksboro.yaml", "--terrain", "jacksboro.tif", "--plot", "jacksboro.png",
        "--geojson", "jacksboro.geojson", cwd=tmp_path,
    )  # fmt: skip
    assert got.returncode == 0, got.stderr
    shown = _fenced("text", "terrain-jacksboro:").splitlines()
    printed = got.stdout.splitlines()
    # the compute time is the machine's; every other figure is the plan's
    assert [ln for ln in printed if "compute" not in ln] == [ln for ln in shown if "compute" not in ln]


def test_the_hillshade_agrees_with_gdaldem_on_the_jacksboro_ground(ground: Path) -> None:
    """``gdaldem hillshade`` (Horn's 3 x 3 gradient, sun at 315 / 45) on the plane the plot draws."""
    import os
    import shutil
    import subprocess

    import rasterio
    from rasterio.transform import from_origin

    from pfp_service.render.terrain_layers import hillshade
    from pfp_service.scenario import load_scenario
    from pfp_service.terrain.planning import prepare

    gdaldem = shutil.which("gdaldem")
    if gdaldem is None:
        what = "no gdaldem: apt-get install gdal-bin (.ci/ensure-gdal)"
        if os.environ.get("CI"):
            pytest.fail(f"{what} (CI is set: the comparison with GDAL must run)")
        pytest.skip(what)
    sc = load_scenario(ground / "with.yaml")
    g = prepare(
        str(ground / "jacksboro.tif"), None, [sc.start, sc.goal, *(s.threat.xi for s in sc.schedule())], None,
        sc.unit.mobility(),
    ).grid  # fmt: skip
    assert np.isfinite(g.z).all()
    # the plane as a raster whose rows run south (GDAL's order) and whose cells are metres: any
    # projected CRS serves, gdaldem uses only the cell size
    src, out = ground / "plane.tif", ground / "shade.tif"
    with rasterio.open(
        src, "w", driver="GTiff", width=g.shape[1], height=g.shape[0], count=1, dtype="float64",
        crs="EPSG:32616", transform=from_origin(0.0, g.cell_m * g.shape[0], g.cell_m, g.cell_m),
    ) as f:  # fmt: skip
        f.write(g.z[::-1], 1)
    subprocess.run([gdaldem, "hillshade", "-q", str(src), str(out)], check=True, timeout=120)
    with rasterio.open(out) as f:
        theirs = f.read(1)[::-1].astype(float)  # bytes: 0 no data (the edge), 1 + 254 cos
    ours = 1.0 + 254.0 * hillshade(g.z, g.cell_m)
    inner = theirs > 0
    diff = np.abs(ours - theirs)[inner]
    # the same light and the same cosine; the gradients differ (central differences here, Horn's
    # weighted 3 x 3 there), which on ridge-and-valley ground moves a cell by a few levels of 255
    assert inner.mean() > 0.95
    assert np.median(diff) <= 2.0 and np.quantile(diff, 0.99) <= 12.0, (
        np.median(diff),
        np.quantile(diff, 0.99),
    )
    assert np.corrcoef(ours[inner], theirs[inner])[0, 1] > 0.99
