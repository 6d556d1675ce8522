"""A controller's link over terrain: the line of sight between two units (checked against Franklin's exact
ray, which the viewshed is checked against GDAL with), and the live world keeping a robot in its controller's
sight, and holding it at the next direction once its controller stops."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import PlannerParams
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.link_sight import sees
from pfp_service.terrain.live import of_grid
from pfp_service.terrain.viewshed import exact_lowest_visible_height
from pfp_service.wire import Goal
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.world import GoalSet, TeamPut, World, WorldSettings
from tests.unit.test_world_teams import _drive, _report

pytestmark = pytest.mark.unit

CELL_M = 20.0
XS = np.arange(101) * CELL_M - 1000.0


def _ridge_grid() -> TerrainGrid:
    """Flat ground at 100 m with a ridge 40 m high along x = 300 m, and a gentle swell across it."""
    gx, gy = np.meshgrid(XS, XS)
    z = 100.0 + 40.0 * np.exp(-((gx - 300.0) ** 2) / (2 * 60.0**2)) + 6.0 * np.sin(gy / 170.0)
    return TerrainGrid(-1000.0, -1000.0, CELL_M, z)


@pytest.mark.parametrize("seed", range(4))
def test_line_of_sight_agrees_with_the_exact_ray_at_grid_points(seed: int) -> None:
    rng = np.random.default_rng(seed)
    grid = _ridge_grid()
    mast = 2.0
    agree = disagree = seen = hidden = 0
    for _ in range(150):
        (r0, c0), (r1, c1) = rng.integers(5, 96, size=(2, 2))
        if (r0, c0) == (r1, c1):
            continue
        low = exact_lowest_visible_height(grid.z, (int(r0), int(c0)), mast, np.array([[r1, c1]]), CELL_M)[0]
        truth = low <= mast
        a, b = (float(XS[c0]), float(XS[r0])), (float(XS[c1]), float(XS[r1]))
        if abs(low - mast) < 0.5:  # within half a metre of the mast: the two samplings may differ
            continue
        got = sees(grid, a, b, mast)
        agree += got == truth
        disagree += got != truth
        seen += truth
        hidden += not truth
    assert disagree == 0, f"seed {seed}: {disagree} of {agree + disagree}"
    assert seen >= 10 and hidden >= 10, (seen, hidden)  # both answers were asked for


def test_unknown_ground_hides_nothing_and_a_line_in_one_cell_sees() -> None:
    grid = _ridge_grid()
    z = grid.z.copy()
    z[:, 55:75] = np.nan  # unknown ground where the ridge stands
    holed = TerrainGrid(grid.x0_m, grid.y0_m, CELL_M, z)
    assert not sees(grid, (0.0, 0.0), (600.0, 0.0), 2.0)
    assert sees(holed, (0.0, 0.0), (600.0, 0.0), 2.0)
    assert sees(holed, (250.0, 0.0), (250.0, 30.0), 2.0)  # both ends on unknown ground
    assert sees(grid, (0.0, 0.0), (0.0, 0.0), 2.0)


def test_a_robot_keeps_its_controllers_line_of_sight_over_a_ridge_then_holds_when_the_controller_stops() -> (
    None
):
    ground = of_grid(_ridge_grid())
    w = World(
        WorldSettings(
            planner=PlannerParams(intensity="density", step=0.5), terrain=ground, bounds=ground.bounds
        )
    )
    w.apply([TeamPut("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=1500.0))], 0.0)
    tracks, said = _drive(
        w,
        start={"r1": (100.0, 0.0), "m1": (0.0, 0.0)},
        goal={"r1": (600.0, 0.0), "m1": (150.0, 0.0)},
        speed={"r1": 3.0, "m1": 0.5},
        seconds=150.0,
    )
    robot, ctl = tracks["r1"], tracks["m1"]
    assert all(
        sees(ground.grid, c, r, ground.unit.height_m) for c, r in zip(ctl, robot)
    )  # never out of sight
    assert 250.0 < max(p[0] for p in robot) < 600.0  # it went up the ridge, and no further than seen
    assert any("out of m1's line of sight" in d.reason for d in said if d.unit == "r1")
    assert math.dist(robot[-1], ctl[-1]) < 1500.0 / 2  # the ground held it, well within radio range
    # its controller stops: the robot's very next direction holds it
    at = {"r1": robot[-1], "m1": ctl[-1]}
    w.apply([GoalSet("r1", Goal(position=(200.0, 50.0), tolerance=1.0))], 151.0)
    out = w.apply([_report("m1", at["m1"], 0.0), _report("r1", at["r1"], 1.0)], 152.0)
    (d,) = [d for d in out.directions if d.unit == "r1"]
    assert d.vector == (0.0, 0.0) and d.reach_m == 0.0
    assert d.reason == "team alpha: lost link: controller m1 has stopped"


@pytest.mark.parametrize("seed", range(3))
def test_line_of_sight_off_grid_agrees_with_the_bilinear_ground_sampled_finely(seed: int) -> None:
    """Between grid points the ground is bilinear, a parabola along a line within a cell: a crest between
    two half-cell samples hides as much as one on them (a half-cell sampling missed some)."""
    from scipy.interpolate import RegularGridInterpolator

    rng = np.random.default_rng(seed)
    z = 100.0 + rng.normal(0.0, 2.0, (101, 101))  # rough ground: crests everywhere between samples
    grid = TerrainGrid(-1000.0, -1000.0, CELL_M, z)
    ground = RegularGridInterpolator((XS, XS), z)
    mast = 2.0
    wrong = seen = hidden = 0
    for _ in range(300):
        a = rng.uniform(-800.0, 800.0, 2)
        b = a + rng.uniform(-120.0, 120.0, 2)
        f = np.linspace(0.0, 1.0, int(np.hypot(*(b - a)) / CELL_M * 200) + 2)
        pts = a + (b - a) * f[:, None]
        zz = ground(pts[:, ::-1])
        over = zz[1:-1] - ((zz[0] + mast) + (zz[-1] - zz[0]) * f[1:-1])
        if abs(over.max()) < 0.01:
            continue  # grazing: the fine sampling itself is not that sure
        truth = over.max() < 0.0
        wrong += sees(grid, (a[0], a[1]), (b[0], b[1]), mast) != truth
        seen += truth
        hidden += not truth
    assert wrong == 0 and seen >= 10 and hidden >= 10, (wrong, seen, hidden)
