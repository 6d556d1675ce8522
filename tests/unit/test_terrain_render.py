"""The ground under a plan's plot: hillshade on surfaces whose lighting is known, and the plot's layers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.render.terrain_layers import SUN_ALTITUDE_DEG, hillshade

pytestmark = pytest.mark.unit

CELL_M = 30.0


def plane(dz_dx: float, dz_dy: float, n: int = 12) -> np.ndarray:
    """A plane ``z = dz_dx x + dz_dy y`` sampled as ``TerrainGrid.z`` (rows running north)."""
    x = CELL_M * np.arange(n)
    gx, gy = np.meshgrid(x, x)
    return dz_dx * gx + dz_dy * gy


def facing(azimuth_deg: float, slope_deg: float) -> np.ndarray:
    """A plane whose downhill side faces ``azimuth_deg`` (compass), ``slope_deg`` steep."""
    g = math.tan(math.radians(slope_deg))
    az = math.radians(azimuth_deg)
    return plane(-g * math.sin(az), -g * math.cos(az))


def test_flat_ground_is_lit_by_the_sine_of_the_suns_altitude() -> None:
    for alt in (10.0, 45.0, 80.0):
        got = hillshade(plane(0.0, 0.0), CELL_M, 123.0, alt)
        assert np.allclose(got, math.sin(math.radians(alt)), atol=1e-12)


def test_a_plane_tilted_straight_at_the_sun_is_uniformly_and_fully_lit() -> None:
    # facing the sun (north-west), tilted so its normal points at it: 90 - altitude degrees
    got = hillshade(facing(315.0, 90.0 - SUN_ALTITUDE_DEG), CELL_M)
    assert np.allclose(got, 1.0, atol=1e-12)
    # any plane is uniformly lit, edges included (one-sided differences are exact on a plane)
    tilted = hillshade(facing(200.0, 20.0), CELL_M)
    assert np.ptp(tilted) < 1e-12


def test_ground_facing_away_from_the_sun_steeper_than_its_altitude_is_unlit() -> None:
    assert np.all(hillshade(facing(135.0, SUN_ALTITUDE_DEG + 5.0), CELL_M) == 0.0)
    # and the same slope turned to the sun is brighter than flat ground
    toward = hillshade(facing(315.0, 20.0), CELL_M)[0, 0]
    away = hillshade(facing(135.0, 20.0), CELL_M)[0, 0]
    flat = hillshade(plane(0.0, 0.0), CELL_M)[0, 0]
    assert away < flat < toward


def test_the_exact_cosine_for_any_plane_and_sun() -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        az, alt = rng.uniform(0, 360), rng.uniform(5, 85)
        aspect, slope = rng.uniform(0, 360), rng.uniform(0, 60)
        got = hillshade(facing(aspect, slope), CELL_M, az, alt)[3, 4]
        # spherical law of cosines between the ground's normal (the zenith tilted by the slope
        # toward its aspect) and the sun
        want = math.sin(math.radians(alt)) * math.cos(math.radians(slope)) + math.cos(
            math.radians(alt)
        ) * math.sin(math.radians(slope)) * math.cos(math.radians(az - aspect))
        assert got == pytest.approx(max(want, 0.0), abs=1e-9), (az, alt, aspect, slope)


def test_rows_run_north_as_the_terrain_grid_does() -> None:
    # a slope rising to the north faces south: lit by a southern sun, dark under a northern one
    rising_north = plane(0.0, 1.0)
    assert hillshade(rising_north, CELL_M, 180.0, 30.0)[0, 0] > 0.9
    assert hillshade(rising_north, CELL_M, 0.0, 30.0)[0, 0] == 0.0


def test_unknown_ground_stays_unknown_and_a_tiny_grid_is_refused() -> None:
    z = plane(0.1, 0.0)
    z[5, 5] = np.nan
    got = hillshade(z, CELL_M)
    assert np.isnan(got[5, 5]) and np.isnan(got[5, 4]) and np.isfinite(got[0, 0])
    with pytest.raises(ValueError):
        hillshade(np.zeros((1, 5)), CELL_M)


SCENARIO = """\
name: jacksboro
unit: {class: foot}
start: [-3000, -3000]
goal: [3000, 3000]
threats:
  - {position: [0, 500], facing_deg: 200, sigma_range: 800, sigma_lateral: 600, skew: 1}
  - {position: [1500, -1000], facing_deg: 300, sigma_range: 700, sigma_lateral: 500, skew: 1}
"""


@pytest.fixture(scope="module")
def planned(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """The scenario over the Jacksboro DEM as ``pfp plan`` plans it: (scenario, result, terrain)."""
    import msgspec

    from pfp_service.core import plan
    from pfp_service.core.zones import ZoneSet
    from pfp_service.scenario import load_scenario
    from pfp_service.terrain.planning import prepare, profile
    from tests import terrain_data

    d = tmp_path_factory.mktemp("render")
    dem = str(terrain_data.write_geographic(d / "jacksboro.tif"))
    (d / "s.yaml").write_text(SCENARIO)
    sc = load_scenario(d / "s.yaml")
    sched = sc.schedule()
    g = prepare(dem, None, [sc.start, sc.goal, *(s.threat.xi for s in sched)], None, sc.unit.mobility())
    params = sc.planner.to_params()
    r = plan(sc.start, sc.goal, sched, params, g.bounds, zones=ZoneSet(g.zones), sight=g.sight)
    r = msgspec.structs.replace(r, **profile(r, g, sched, params.intensity))
    return sc, r, g


def _pixels(fig, ax, xy: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The RGB (0-255) of the rendered figure at data points ``xy``."""
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    px = ax.transData.transform(xy)  # display pixels, origin at the bottom left
    cols = np.round(px[:, 0]).astype(int)
    rows = rgba.shape[0] - 1 - np.round(px[:, 1]).astype(int)
    return rgba[rows, cols, :3].astype(float)


def test_the_plot_shows_lit_ground_brighter_than_shaded_ground(planned) -> None:  # type: ignore[no-untyped-def]
    import matplotlib.pyplot as plt

    from pfp_service.core import ThreatField
    from pfp_service.render.plots import plan_figure

    sc, r, g = planned
    fig = plan_figure(sc, r, terrain=g)
    try:
        ax = fig.axes[0]
        x0, x1 = ax.get_xlim()
        y0, y1 = ax.get_ylim()
        ny, nx = g.grid.shape
        gx, gy = np.meshgrid(
            g.grid.x0_m + g.grid.cell_m * np.arange(nx), g.grid.y0_m + g.grid.cell_m * np.arange(ny)
        )
        shade = hillshade(g.grid.z, g.grid.cell_m)
        level = ThreatField([s.threat for s in sc.schedule()], "peak").level(np.stack([gx, gy], axis=-1))
        inner = (gx > x0 + 200) & (gx < x1 - 200) & (gy > y0 + 200) & (gy < y1 - 200)
        # away from the threats, whose level and sight are drawn over the ground
        clear = inner & (level < 1e-4) & np.isfinite(shade)
        lit, dark = np.quantile(shade[clear], [0.95, 0.05])
        bright = np.column_stack([gx[clear & (shade >= lit)], gy[clear & (shade >= lit)]])
        dim = np.column_stack([gx[clear & (shade <= dark)], gy[clear & (shade <= dark)]])
        assert len(bright) > 20 and len(dim) > 20
        luminance_lit = np.median(_pixels(fig, ax, bright).mean(axis=1))
        luminance_dark = np.median(_pixels(fig, ax, dim).mean(axis=1))
        assert luminance_lit - luminance_dark > 60, (luminance_lit, luminance_dark)
        # the ground each threat sees is drawn, one image per threat over the hillshade
        assert len(ax.images) == 1 + 2
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert "t1 sees a unit here" in labels and "t2 sees a unit here" in labels
        assert any(t.startswith("elevation, every") for t in labels)
        assert any(t.startswith("ground steeper than 30") for t in labels)
    finally:
        plt.close(fig)


def test_a_threat_sees_its_own_ground_and_not_behind_the_ridge(planned) -> None:  # type: ignore[no-untyped-def]
    from pfp_service.render.terrain_layers import sight_masks

    sc, r, g = planned
    threats = [s.threat for s in sc.schedule()]
    masks = sight_masks(threats, "peak", g)
    assert [m.id for m in masks] == ["t1", "t2"]
    for m, t in zip(masks, threats, strict=True):
        i = round((t.xi[0] - m.x0_m) / m.cell_m)
        k = round((t.xi[1] - m.y0_m) / m.cell_m)
        assert m.seen[k, i]  # where it stands
        assert 0 < m.seen.mean() < 1  # the ground hides some of its zone
    # the plan's own measure agrees: where the path is in a threat's view, its mask is seen there
    for v, m in zip(r.in_view, masks, strict=True):
        if v.metres == 0:
            continue
        path = np.asarray(r.path)
        i = np.round((path[:, 0] - m.x0_m) / m.cell_m).astype(int)
        k = np.round((path[:, 1] - m.y0_m) / m.cell_m).astype(int)
        ok = (i >= 0) & (i < m.seen.shape[1]) & (k >= 0) & (k < m.seen.shape[0])
        assert m.seen[k[ok], i[ok]].any()


def test_without_terrain_the_plot_has_no_ground(planned) -> None:  # type: ignore[no-untyped-def]
    import matplotlib.pyplot as plt

    from pfp_service.render.plots import plan_figure

    sc, r, _ = planned
    fig = plan_figure(sc, r)
    try:
        ax = fig.axes[0]
        assert len(ax.images) == 0
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert not any("sees" in t or "elevation" in t for t in labels)
        assert fig.axes[1].get_xlabel() == "threat level"
    finally:
        plt.close(fig)


def test_the_shading_stops_at_a_ridge_and_a_threat_off_the_ground_gets_none() -> None:
    from types import SimpleNamespace

    from pfp_service.core import Threat
    from pfp_service.render.terrain_layers import sight_masks
    from pfp_service.terrain.grid import TerrainGrid
    from pfp_service.terrain.threat_sight import TerrainSight

    # flat ground with a 60 m wall running north-south at x = 0
    xs = np.arange(-2000.0, 2001.0, 20.0)
    gx, _ = np.meshgrid(xs, xs)
    grid = TerrainGrid(-2000.0, -2000.0, 20.0, np.where(np.abs(gx) <= 40.0, 60.0, 0.0))
    terrain = SimpleNamespace(sight=TerrainSight(grid, 1.8))
    west = Threat.from_facing((-600.0, 0.0), 90.0, 300.0, 300.0, 0.0, 1.0, "west")
    off = Threat.from_facing((9000.0, 0.0), 90.0, 300.0, 300.0, 0.0, 1.0, "off")
    (mask,) = sight_masks([west, off], "peak", terrain)  # type: ignore[arg-type]
    assert mask.id == "west"
    ny, nx = mask.seen.shape
    x = mask.x0_m + mask.cell_m * np.arange(nx)
    row = mask.seen[ny // 2]
    assert row[(x > -500) & (x < -100)].all()  # its own side of the wall, in the open
    assert not row[(x > 200) & (x < 600)].any()  # in the wall's lee, close behind it
