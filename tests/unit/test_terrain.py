"""Terrain in process: analytic viewsheds with exact answers, the sweep against exact rays, reading the three
formats, placing a DEM on the planner's plane, smooth sampling, and hostile rasters refused."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.terrain.dem import info, read_dem
from pfp_service.terrain.grid import TerrainGrid, load
from pfp_service.terrain.viewshed import (
    EARTH_RADIUS_M,
    exact_lowest_visible_height,
    lowest_visible_height,
    visible,
)
from tests import terrain_data

pytestmark = pytest.mark.unit


@pytest.fixture(scope="module")
def dems(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return terrain_data.build(tmp_path_factory.mktemp("dem"))


def _all_cells(shape: tuple[int, int]) -> np.ndarray:
    rr, cc = np.indices(shape)
    return np.column_stack([rr.ravel(), cc.ravel()])


def _both(z, obs, eye_m, dx, dy=None, curvature=0.0):
    """(sweep, exact) lowest visible heights for every cell, no radius."""
    fast = lowest_visible_height(z, obs, eye_m, math.inf, dx, dy, curvature)
    exact = exact_lowest_visible_height(z, obs, eye_m, _all_cells(z.shape), dx, dy, curvature).reshape(
        z.shape
    )
    return fast, exact


@pytest.mark.parametrize(("dx", "dy"), [(10.0, 10.0), (7.5, 9.3)])
def test_a_ridge_hides_what_lies_behind_it_by_similar_triangles(dx, dy):
    # a wall of one column, `wall_m` high, across flat ground at 0; the eye `eye_m` above ground at column c0.
    # Behind it a target at column c needs eye + (wall - eye) * (c - c0) / (cw - c0) (the ray crosses the
    # wall's column at that fraction of its length, whatever its row and the cells' shape).
    rows, cols, c0, cw, wall_m, eye_m = 121, 160, 20, 60, 30.0, 2.0
    z = np.zeros((rows, cols))
    z[:, cw] = wall_m
    obs = (rows // 2, c0)
    fast, exact = _both(z, obs, eye_m, dx, dy)
    rr, cc = np.indices(z.shape)
    behind = cc > cw
    expected = eye_m + (wall_m - eye_m) * (cc - c0) / (cw - c0)
    np.testing.assert_allclose(exact[behind], expected[behind], rtol=0, atol=1e-9)
    assert np.all(exact[(cc <= cw) & (cc >= c0)] == 0.0)  # in front of the wall and on it: seen
    # the sweep interpolates along the column lines where |dc| >= |dr|: exact there
    octant = behind & (np.abs(rr - obs[0]) <= cc - c0)
    np.testing.assert_allclose(fast[octant], expected[octant], rtol=0, atol=1e-9)
    for target_m in (0.0, 10.0, 40.0):
        agree = (visible(fast, target_m) == visible(exact, target_m)).mean()
        assert agree >= 0.99, f"target {target_m} m: sweep and rays agree on {agree:.2%}"


@pytest.mark.parametrize("eye_m", [0.0, 1.7, 50.0])
def test_everything_is_seen_from_the_apex_of_a_cone(eye_m):
    n, c = 161, 80
    rr, cc = np.indices((n, n))
    z = 900.0 - 0.35 * np.hypot(rr - c, cc - c) * 10.0
    fast, exact = _both(z, (c, c), eye_m, 10.0)
    assert np.all(fast < 1e-9) and np.all(exact < 1e-9)  # 0 but for rounding where the sight line grazes


def test_everything_is_seen_from_the_bottom_of_a_pit_but_not_its_floor_from_beside_it():
    n, c = 161, 80
    rr, cc = np.indices((n, n))
    r = np.hypot(rr - c, cc - c)
    bowl = 0.4 * r * 10.0
    fast, exact = _both(bowl, (c, c), 1.0, 10.0)
    assert np.all(fast < 1e-9) and np.all(exact < 1e-9)  # 0 but for rounding where the sight line grazes
    # a shaft 30 m deep, 10 cells wide, in flat ground: from 40 cells away at 2 m its far floor is hidden
    z = np.zeros((n, n))
    shaft = (np.abs(rr - c) <= 5) & (np.abs(cc - c) <= 5)
    z[shaft] = -30.0
    fast, exact = _both(z, (c, c - 40), 2.0, 10.0)
    far_floor = shaft & (cc == c + 5) & (rr == c)
    # the ray grazes the near rim (cell c - 6 is ground at 0, c - 5 the floor); the floor at c + 5 is
    # 45 cells out, the rim crossing at 34 (flat ground, interpolation exact): similar triangles again
    expected = 2.0 - 2.0 * 45 / 34 + 30.0
    assert exact[far_floor][0] == pytest.approx(expected, abs=1e-9)
    assert fast[far_floor][0] == pytest.approx(expected, abs=1e-9)


def test_curvature_lowers_the_far_ground_as_a_sphere_would():
    # flat ground on a sphere of radius R/k: from an eye h up the horizon lies at s = sqrt(2 R h / k), and a
    # target at d > s must stand k (d - s)^2 / (2 R) above the ground
    k, eye_m, cell_m = 0.85714, 2.0, 10.0
    z = np.zeros((3, 1200))
    fast, exact = _both(z, (1, 0), eye_m, cell_m, curvature=k)
    d = np.arange(z.shape[1]) * cell_m
    s = math.sqrt(2 * EARTH_RADIUS_M * eye_m / k)
    expected = np.where(d > s, k * (d - s) ** 2 / (2 * EARTH_RADIUS_M), 0.0)
    np.testing.assert_allclose(exact[1], expected, atol=2e-3)  # the horizon is sampled every cell
    np.testing.assert_allclose(fast[1], expected, atol=2e-3)


def test_the_sweep_agrees_with_exact_rays_on_rough_ground():
    from scipy.ndimage import gaussian_filter

    seed = 20_261_205
    rng = np.random.default_rng(seed)
    z = gaussian_filter(rng.normal(size=(301, 301)), 6) * 2_000.0
    fast, exact = _both(z, (150, 140), 3.0, 20.0, 25.0)
    for target_m in (0.0, 5.0):
        agree = (visible(fast, target_m) == visible(exact, target_m)).mean()
        assert agree >= 0.97, f"seed {seed}, target {target_m} m: {agree:.2%}"


def test_the_radius_bounds_the_answer_and_unknown_ground_hides_nothing():
    z = np.zeros((101, 101))
    z[50, 60] = np.nan
    z[:, 70] = 500.0
    z[40:61, 70] = np.nan  # a gap of unknown ground in the wall: sight passes through it
    low = lowest_visible_height(z, (50, 50), 2.0, 300.0, 10.0)
    rr, cc = np.indices(z.shape)
    d = np.hypot(rr - 50, cc - 50) * 10.0
    assert np.all(np.isnan(low[d > 300.0])) and np.all(np.isfinite(low[d <= 300.0]))
    assert low[50, 60] == 0.0 and low[50, 80] == 0.0
    with pytest.raises(ValueError, match="unknown ground"):
        lowest_visible_height(z, (50, 60), 2.0, 300.0, 10.0)


def test_terrain_grid_samples_a_plane_exactly_with_its_gradient():
    a, b, c0 = 0.12, -0.05, 300.0
    xs, ys = np.arange(40) * 25.0 - 500.0, np.arange(30) * 25.0 - 200.0
    gx, gy = np.meshgrid(xs, ys)
    grid = TerrainGrid(-500.0, -200.0, 25.0, a * gx + b * gy + c0)
    rng = np.random.default_rng(3)
    px, py = rng.uniform(-500, 475, 1000), rng.uniform(-200, 525, 1000)
    np.testing.assert_allclose(grid.elevation(px, py), a * px + b * py + c0, atol=1e-9)
    ex, ey = grid.gradient(px, py)
    np.testing.assert_allclose(ex, a, atol=1e-12)
    np.testing.assert_allclose(ey, b, atol=1e-12)
    np.testing.assert_allclose(grid.slope_deg(px, py), math.degrees(math.atan(math.hypot(a, b))), atol=1e-9)
    assert np.isnan(grid.elevation(np.array([-501.0, 0.0]), np.array([0.0, 526.0]))).all()


def test_terrain_grid_gradient_is_the_derivative_of_its_elevation():
    rng = np.random.default_rng(11)
    grid = TerrainGrid(0.0, 0.0, 30.0, rng.uniform(0, 200, (20, 20)))
    # points off the cell edges, so the bilinear surface is smooth around each
    i, j = rng.integers(0, 19, 500), rng.integers(0, 19, 500)
    px, py = (i + rng.uniform(0.1, 0.9, 500)) * 30.0, (j + rng.uniform(0.1, 0.9, 500)) * 30.0
    h = 1e-4
    fx = (grid.elevation(px + h, py) - grid.elevation(px - h, py)) / (2 * h)
    fy = (grid.elevation(px, py + h) - grid.elevation(px, py - h)) / (2 * h)
    gx, gy = grid.gradient(px, py)
    np.testing.assert_allclose(gx, fx, atol=1e-6)
    np.testing.assert_allclose(gy, fy, atol=1e-6)


def test_info_reads_each_format(dems):
    z, west, north, step = terrain_data.jacksboro()
    for kind, path in dems.items():
        d = info(str(path))
        s, w, n, e = d.bounds_latlon
        assert s <= north - z.shape[0] * step + 1e-6 and n >= north - 1e-6, kind
        assert w <= west + 1e-6 and e >= west + z.shape[1] * step - 1e-6, kind
        assert d.elevation_min_m == z.min() or kind == "utm", kind  # UTM is resampled: within the range
        assert z.min() <= d.elevation_min_m <= d.elevation_max_m <= z.max(), kind
        # 3" is 92.6 m north-south and 74.5 m east-west at 36.6 N
        assert (
            d.resolution_m[1] == pytest.approx(3 / 3600 * math.pi / 180 * 6_367_000, rel=0.01)
            or kind == "utm"
        )
    assert info(str(dems["dted"])).driver == "DTED"


def test_placing_the_three_files_gives_the_same_ground(dems):
    z, west, north, step = terrain_data.jacksboro()
    origin = Origin(lat=north - z.shape[0] * step / 2, lon=west + z.shape[1] * step / 2)
    bounds = (-9_000.0, -9_000.0, 9_000.0, 9_000.0)
    grids = {k: load(str(p), origin, bounds, 50.0) for k, p in dems.items()}
    g, d, u = grids["geographic"].z, grids["dted"].z, grids["utm"].z
    assert np.isfinite(g).all()
    np.testing.assert_allclose(d, g, atol=1e-6)  # the same posts: the same grid
    diff = np.abs(u - g)
    # UTM was resampled once more (bilinear at 83 m): the same ground within a few metres but on cliffs
    assert np.median(diff) < 3.0 and np.percentile(diff, 99) < 30.0, (
        np.median(diff),
        np.percentile(diff, 99),
    )
    # the grid's own corner is the DEM's cell there: the placement is not shifted or mirrored
    lat, lon = origin.to_geodetic(0.0, 0.0)
    row, col = (north - lat) / step - 0.5, (lon - west) / step - 0.5
    j, i = grids["geographic"].cell_of(0.0, 0.0)
    r0, c0 = math.floor(row), math.floor(col)
    corners = z[r0 : r0 + 2, c0 : c0 + 2].astype(float)
    assert corners.min() - 1e-9 <= g[j, i] <= corners.max() + 1e-9


def test_an_area_outside_the_dem_is_refused(dems):
    with pytest.raises(InputError, match="does not cover the area"):
        read_dem(str(dems["geographic"]), (36.0, -84.3, 36.2, -84.2))
    origin = Origin(lat=36.6, lon=-84.2)
    with pytest.raises(InputError, match="does not cover the area") as caught:
        load(str(dems["utm"]), origin, (-5_000.0, -5_000.0, 30_000.0, 5_000.0), 50.0)  # 30 km east: past it
    assert caught.value.path == str(dems["utm"])


def _write(path: Path, **kw) -> Path:
    import rasterio

    data = kw.pop("data", None)
    with rasterio.open(
        path, "w", driver="GTiff", count=kw.pop("count", 1), dtype=kw.pop("dtype", "int16"), **kw
    ) as out:
        if data is not None:
            out.write(data, 1)
    return path


def test_hostile_and_foreign_rasters_are_refused(tmp_path):
    from rasterio.crs import CRS
    from rasterio.transform import from_origin

    geo = {"crs": "EPSG:4326", "transform": from_origin(-84.0, 36.0, 0.001, 0.001)}
    text = tmp_path / "notes.tif"
    text.write_text("not a raster\n")
    cases = {
        "is not a DEM": text,
        "a side": _write(tmp_path / "huge.tif", width=2_000_000, height=2, tiled=True, sparse_ok=True, **geo),
        "blocks of": _write(
            tmp_path / "bomb.tif", width=8_000, height=1_000, blockysize=1_000, compress="deflate", **geo
        ),
        "has 3 bands": _write(tmp_path / "rgb.tif", width=10, height=10, count=3, dtype="uint8", **geo),
        "no coordinate reference system": _write(
            tmp_path / "nocrs.tif", width=10, height=10, data=np.zeros((10, 10), np.int16)
        ),
        "CRS cannot be placed": _write(
            tmp_path / "local.tif",
            width=10,
            height=10,
            data=np.zeros((10, 10), np.int16),
            crs=CRS.from_wkt(
                'LOCAL_CS["site grid",LOCAL_DATUM["site",0],UNIT["metre",1],AXIS["E",EAST],AXIS["N",NORTH]]'
            ),
            transform=from_origin(0.0, 100.0, 10.0, 10.0),
        ),
        "is a directory": tmp_path,
        "cannot read": tmp_path / "missing.tif",
    }
    for reason, path in cases.items():
        with pytest.raises(InputError, match=reason) as caught:
            info(str(path))
        assert caught.value.path == str(path)


def test_info_on_more_cells_than_dem_cells_reads_an_overview_or_nothing(tmp_path):
    import rasterio
    from rasterio.enums import Resampling
    from rasterio.transform import from_origin
    from rasterio.windows import Window

    from pfp_service.bounds import LIMITS

    side = math.isqrt(LIMITS["dem_cells"].value) + 256  # just past the budget
    path = tmp_path / "big.tif"
    with rasterio.open(
        path, "w", driver="GTiff", width=side, height=side, count=1, dtype="int16", nodata=-32768,
        crs="EPSG:4326", transform=from_origin(-84.0, 36.0, 1e-5, 1e-5), tiled=True, sparse_ok=True,
    ) as out:  # fmt: skip
        out.write(np.full((256, 256), 123, np.int16), 1, window=Window(512, 512, 256, 256))
    blind = info(str(path))
    assert blind.elevation_min_m is None and blind.elevation_sampled
    with rasterio.open(path, "r+") as f:
        f.build_overviews([4], Resampling.nearest)
    seen = info(str(path))
    assert seen.elevation_min_m == seen.elevation_max_m == 123.0 and seen.elevation_sampled


def _rough(seed: int, shape: tuple[int, int], sigma: float) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(np.random.default_rng(seed).normal(size=shape), sigma) * 3_000.0


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    rows=st.integers(3, 40),
    cols=st.integers(3, 40),
    fr=st.floats(0, 1),
    fc=st.floats(0, 1),
    dx=st.floats(1.0, 100.0),
    dy=st.floats(1.0, 100.0),
)
def test_mirroring_and_transposing_the_ground_mirror_and_transpose_the_viewshed(
    seed, rows, cols, fr, fc, dx, dy
):
    z = _rough(seed, (rows, cols), 2.0)
    obs = (min(rows - 1, int(fr * rows)), min(cols - 1, int(fc * cols)))
    for method in ("sweep", "exact"):

        def run(zz, o, a, b):
            if method == "sweep":
                return lowest_visible_height(zz, o, 2.0, math.inf, a, b)
            return exact_lowest_visible_height(zz, o, 2.0, _all_cells(zz.shape), a, b).reshape(zz.shape)

        base = run(z, obs, dx, dy)
        np.testing.assert_allclose(
            run(z.T, obs[::-1], dy, dx), base.T, atol=1e-9, err_msg=f"{method} seed {seed}"
        )
        np.testing.assert_allclose(
            run(z[::-1, ::-1], (rows - 1 - obs[0], cols - 1 - obs[1]), dx, dy),
            base[::-1, ::-1],
            atol=1e-9,
            err_msg=f"{method} seed {seed}",
        )


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), eye=st.floats(0.0, 50.0), more=st.floats(0.0, 200.0))
def test_a_higher_eye_never_hides_what_a_lower_one_saw(seed, eye, more):
    # the sight line from a higher eye to the same target point lies above the lower one's all the way
    z = _rough(seed, (41, 41), 3.0)
    cells = _all_cells(z.shape)
    low = exact_lowest_visible_height(z, (20, 20), eye, cells, 10.0)
    high = exact_lowest_visible_height(z, (20, 20), eye + more, cells, 10.0)
    assert np.all(high <= low + 1e-9), f"seed {seed}"
    fast = lowest_visible_height(z, (20, 20), eye, math.inf, 10.0).ravel()
    agree = (visible(fast, 0.0) == visible(low, 0.0)).mean()
    assert agree >= 0.95, f"seed {seed}: sweep and rays agree on {agree:.2%}"
