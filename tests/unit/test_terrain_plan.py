"""Planning over terrain, in process: threats masked by line of sight, slope barriers, and live == preview.

Analytic ground first (a ridge, a cliff round a plateau), where what must
happen is known; then the Jacksboro DEM, on seeded scenarios.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Scheduled, Threat, ThreatField, kernels, plan
from pfp_service.core.mobility import CLASSES
from pfp_service.core.plan import walk_many
from pfp_service.core.stepper import Stepper
from pfp_service.core.zones import ZoneSet
from pfp_service.terrain.barriers import barrier_cells, barrier_zones
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.threat_sight import TerrainSight

pytestmark = pytest.mark.unit

FOOT = CLASSES["foot"]


def _grid(fn, half_m: float = 3000.0, cell_m: float = 20.0) -> TerrainGrid:
    xs = np.arange(-half_m, half_m + cell_m / 2, cell_m)
    gx, gy = np.meshgrid(xs, xs)
    return TerrainGrid(-half_m, -half_m, cell_m, fn(gx, gy))


def _ridge(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A north-south ridge 60 m high along x = 0, 600 m wide at its foot (about 11 degrees)."""
    return np.maximum(0.0, 60.0 - 0.2 * np.abs(x))


RIDGE = _grid(_ridge)
# west of the ridge, facing east across it: blind to terrain it covers the valley at x = 600
BEHIND = Threat.from_facing((-1000.0, 0.0), 90.0, 800.0, 800.0, 0.0, 1.0, "ridge", observer_height_m=2.0)


def _fields(grid: TerrainGrid, threats: list[Threat]) -> tuple[ThreatField, ThreatField]:
    return ThreatField(threats), ThreatField(threats, sight=TerrainSight(grid, FOOT.height_m))


def test_a_threat_behind_a_ridge_does_not_see_the_valley() -> None:
    blind, seen = _fields(RIDGE, [BEHIND])
    valley = np.array([[x, y] for x in (300.0, 600.0, 1200.0) for y in (-1500.0, 0.0, 1500.0)])
    front = np.array([[x, y] for x in (-1800.0, -600.0, -150.0) for y in (-1500.0, 0.0, 1500.0)])
    assert (blind.level(valley) > 1e-3).all()  # the terrain-blind field prices the valley
    assert (seen.level(valley) < 1e-6 * blind.level(valley)).all()  # ~0 behind the ridge
    # in front of the ridge it sees: the mask leaves at least 99 % (a man in the open, sigmoid(6))
    assert np.all(seen.level(front) >= 0.99 * blind.level(front))


def test_without_a_window_the_field_is_bit_for_bit_the_blind_one() -> None:
    off_grid = Threat.from_facing((50_000.0, 0.0), 90.0, 800.0, 800.0, 0.0, 1.0, "far")
    blind, seen = _fields(RIDGE, [off_grid])
    pts = np.random.default_rng(3).uniform(45_000.0, 55_000.0, (500, 2))
    assert np.array_equal(blind.level(pts), seen.level(pts))
    assert np.array_equal(blind.level_grad(pts)[1], seen.level_grad(pts)[1])


def test_the_masked_gradient_is_the_derivative_of_the_masked_level() -> None:
    _, seen = _fields(RIDGE, [BEHIND])
    # the window is coarser than the grid (WINDOW_SIDE): the gradient is that interpolant's
    x0, y0, cell = (seen.packed[0, c] for c in (kernels.VIS_X0, kernels.VIS_Y0, kernels.VIS_CELL))
    assert cell == 2 * RIDGE.cell_m
    rng = np.random.default_rng(7)
    h = 1e-3
    checked = 0
    for x, y in rng.uniform(-400.0, 400.0, (200, 2)):
        level, gx, gy = seen.level_grad_at(x, y)
        if level < 1e-12:
            continue
        fx = (seen.level_grad_at(x + h, y)[0] - seen.level_grad_at(x - h, y)[0]) / (2 * h)
        fy = (seen.level_grad_at(x, y + h)[0] - seen.level_grad_at(x, y - h)[0]) / (2 * h)
        scale = max(abs(gx), abs(gy), 1e-12)
        # a point within h of a cell edge sees two cells' gradients: skip those, not the rest
        fx_ok = abs((x - x0) / cell - round((x - x0) / cell)) * cell > 2 * h
        fy_ok = abs((y - y0) / cell - round((y - y0) / cell)) * cell > 2 * h
        if fx_ok and fy_ok:
            assert abs(gx - fx) <= 1e-5 * scale and abs(gy - fy) <= 1e-5 * scale, (x, y, gx, fx, gy, fy)
            checked += 1
    assert checked > 100


def _plan(grid: TerrainGrid | None, threats: list[Threat], start, goal, **kw):  # type: ignore[no-untyped-def]
    sched = [Scheduled(t, 0) for t in threats]
    if grid is None:
        return plan(start, goal, sched, PlannerParams(), **kw)
    zones = ZoneSet(barrier_zones(grid, FOOT.max_slope_deg))
    return plan(
        start, goal, sched, PlannerParams(), zones=zones, sight=TerrainSight(grid, FOOT.height_m), **kw
    )


def test_the_route_uses_the_lee_of_the_ridge() -> None:
    start, goal = (600.0, -2500.0), (600.0, 2500.0)
    blind = _plan(None, [BEHIND], start, goal)
    over = _plan(RIDGE, [BEHIND], start, goal)
    assert blind.status.value == over.status.value == "reached"
    _, seen = _fields(RIDGE, [BEHIND])
    from pfp_service.terrain.planning import exposure

    masked_blind = exposure(np.array(blind.path), [Scheduled(BEHIND, 0)], "peak", seen.sight, True)
    # the terrain-blind route detours east round a threat that cannot see it; the terrain route does not
    assert max(x for x, _ in blind.path) > 900.0
    assert max(abs(x - 600.0) for x, _ in over.path) < 50.0
    assert over.length < blind.length
    assert over.exposure <= masked_blind + 1e-12
    assert over.exposure < 1e-6


def _plateau(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A plateau 100 m up, its cliffs 45 degrees, round a circle of 800 m, with a ramp of 10 degrees east."""
    r = np.hypot(x, y)
    cliff = np.clip(100.0 - (r - 800.0), 0.0, 100.0)
    ramp = np.where(
        np.abs(y) < 150.0, np.clip(100.0 - np.tan(np.radians(10.0)) * (x - 800.0), 0.0, 100.0), 0.0
    )
    return np.maximum(cliff, ramp)


PLATEAU = _grid(_plateau)


def _steepest_along(grid: TerrainGrid, path: list[tuple[float, float]]) -> float:
    """The ground's slope along the whole path, sampled every tenth of a cell (not the barriers' own test)."""
    pts = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, math.ceil(math.dist(a, b) / (0.1 * grid.cell_m)))
        pts += [(a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n) for k in range(1, n + 1)]
    arr = np.array(pts)
    return float(np.nanmax(grid.slope_deg(arr[:, 0], arr[:, 1])))


def test_a_slope_barrier_is_never_crossed_and_the_ramp_is_found() -> None:
    steep, _ = barrier_cells(PLATEAU, FOOT.max_slope_deg)
    assert steep.any()
    # from the plain to the plateau's centre: up the ramp, never the cliff
    got = _plan(PLATEAU, [], (2500.0, -2500.0), (0.0, 0.0))
    assert got.status.value == "reached", got.reason
    assert _steepest_along(PLATEAU, got.path) <= FOOT.max_slope_deg + 1e-6
    # a wheeled vehicle (17 degrees) may take the ramp too; tracked as well


def test_a_goal_behind_cliffs_only_is_trapped_naming_the_slope() -> None:
    no_ramp = _grid(lambda x, y: np.clip(100.0 - (np.hypot(x, y) - 800.0), 0.0, 100.0))
    got = _plan(no_ramp, [], (2500.0, -2500.0), (0.0, 0.0))
    assert got.status.value == "trapped", (got.status, got.reason)
    assert "slope>30deg" in got.reason
    assert _steepest_along(no_ramp, got.path) <= FOOT.max_slope_deg + 1e-6


def test_a_stepper_driven_one_step_at_a_time_walks_the_plan_over_terrain() -> None:
    """Live == preview: the stepper a live unit uses, driven a step at a time, and the batch ghosts, give plan()'s path."""
    threats = [BEHIND, Threat.from_facing((1500.0, 800.0), 250.0, 500.0, 400.0, 2.0, 1.0, "open")]
    start, goal = (600.0, -2500.0), (600.0, 2500.0)
    sight = TerrainSight(RIDGE, FOOT.height_m)
    zones = ZoneSet(barrier_zones(RIDGE, FOOT.max_slope_deg))
    field = ThreatField(threats, zones=zones, sight=sight)
    preview = plan(start, goal, [Scheduled(t, 0) for t in threats], PlannerParams(), zones=zones, sight=sight)
    assert preview.status.value == "reached"
    from pfp_service.core.params import resolve

    params = resolve(PlannerParams(), start, goal, threats)
    live = Stepper(start, goal, params)
    x, y = start
    track = [(x, y)]
    for _ in range(params.max_iter):
        adv = live.advise(field, x, y)
        if adv.status.terminal:
            break
        x, y = adv.to
        track.append((x, y))
    assert len(track) == len(preview.path)
    assert np.allclose(track, preview.path, rtol=0.0, atol=1e-9)
    # the batch kernels (descent_many) walk the same ghost
    ghost = walk_many([Stepper(start, goal, params)], field, np.array([start]), 40)[0]
    assert np.allclose(ghost, preview.path[: len(ghost)], rtol=0.0, atol=1e-9)


@pytest.fixture(scope="module")
def jacksboro(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    from tests import terrain_data

    return str(terrain_data.write_geographic(tmp_path_factory.mktemp("dem") / "jacksboro.tif"))


def _reachable(grid: TerrainGrid, limit_deg: float, a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Whether ``a`` and ``b`` lie in one 4-connected region of crossable cells (the DEM's own judgement)."""
    from scipy import ndimage

    steep, unknown = barrier_cells(grid, limit_deg)
    labels, _ = ndimage.label(~(steep | unknown))

    def cell(p: tuple[float, float]) -> int:
        i = min(int((p[0] - grid.x0_m) // grid.cell_m), labels.shape[1] - 1)
        k = min(int((p[1] - grid.y0_m) // grid.cell_m), labels.shape[0] - 1)
        return int(labels[k, i])

    return cell(a) != 0 and cell(a) == cell(b)


def test_on_the_jacksboro_dem_every_reachable_goal_is_reached_over_crossable_ground(jacksboro: str) -> None:
    from pfp_service.terrain.planning import prepare
    from tests.terrain_scenarios import scenario

    base = prepare(jacksboro, None, [(-5000.0, -5000.0), (5000.0, 5000.0)], None, FOOT)
    blind_exposure, masked_exposure = [], []
    for seed in range(8):
        start, goal, sched = scenario(base.grid, seed)
        g = prepare(jacksboro, None, [start, goal, *(s.threat.xi for s in sched)], None, FOOT)
        over = plan(start, goal, sched, PlannerParams(), g.bounds, zones=ZoneSet(g.zones), sight=g.sight)
        blind = plan(start, goal, sched, PlannerParams(), g.bounds)
        if _reachable(g.grid, FOOT.max_slope_deg, start, goal):
            assert over.status.value == "reached", (seed, over.status, over.reason)
        assert _steepest_along(g.grid, over.path) <= FOOT.max_slope_deg + 1e-6, seed
        blind_exposure.append(blind.exposure)
        masked_exposure.append(over.exposure)
    reduction = 1.0 - np.median(np.array(masked_exposure) / np.array(blind_exposure))
    print(f"median exposure reduction over the terrain-blind plans: {reduction:.0%}")
    assert reduction >= 0.30


def test_the_optimal_planner_prices_the_same_masked_field() -> None:
    from pfp_service.core.optimal import plan_optimal

    start, goal = (600.0, -2500.0), (600.0, 2500.0)
    sight = TerrainSight(RIDGE, FOOT.height_m)
    zones = ZoneSet(barrier_zones(RIDGE, FOOT.max_slope_deg))
    sched = [Scheduled(BEHIND, 0)]
    blind = plan_optimal(start, goal, sched, zones=zones)
    over = plan_optimal(start, goal, sched, zones=zones, sight=sight)
    assert over.status.value == "reached" and over.exposure < 1e-6
    assert over.length < blind.length - 100.0  # blind, it detours round a threat that cannot see
    pfp = _plan(RIDGE, [BEHIND], start, goal)
    j, j_star = pfp.length + 10.0 * pfp.exposure, over.length + 10.0 * over.exposure
    assert j <= 1.02 * j_star


def test_the_profile_says_how_long_each_threat_sees_the_path() -> None:
    from pfp_service.terrain.planning import PlanTerrain, profile

    ground = PlanTerrain(
        "ridge",
        None,
        RIDGE,
        FOOT,
        TerrainSight(RIDGE, FOOT.height_m),
        [],
        ((-3000.0, -3000.0), (3000.0, 3000.0)),
    )  # type: ignore[arg-type]
    sched = [Scheduled(BEHIND, 0)]
    lee = _plan(RIDGE, [BEHIND], (600.0, -2500.0), (600.0, 2500.0))
    front = _plan(RIDGE, [BEHIND], (-400.0, -2500.0), (-400.0, 2500.0))
    p_lee, p_front = profile(lee, ground, sched, "peak"), profile(front, ground, sched, "peak")
    assert p_lee["in_view"][0].metres == 0.0  # type: ignore[index]
    assert p_front["in_view"][0].metres > 500.0  # type: ignore[index]  # it starts in view, then climbs to the lee
    # flat valley floor: no climb, Tobler's flat speed; over the ridge's flank: a climb
    assert p_lee["climb_m"] == pytest.approx(0.0, abs=1e-9)
    assert p_lee["eta_s"] == pytest.approx(lee.length / 1.4, rel=1e-9)
    assert p_front["climb_m"] > 0.0 and p_front["exposure_unmasked"] >= front.exposure


def test_a_scenarios_unit_block_picks_a_class_and_overrides_its_fields() -> None:
    from pfp_service.errors import InputError
    from pfp_service.scenario import decode_scenario

    head = b"start: [0, 0]\ngoal: [1000, 0]\n"
    s = decode_scenario(head + b"unit: {class: wheeled, max_slope_deg: 20}\n", "yaml")
    assert s.unit.mobility() == CLASSES["wheeled"].merged(max_slope_deg=20.0)
    assert decode_scenario(head, "yaml").unit.mobility() == FOOT
    t = decode_scenario(
        head + b"threats: [{position: [5, 5], sigma_range: 100, sigma_lateral: 50, observer_height_m: 6}]\n",
        "yaml",
    )
    assert t.schedule()[0].threat.observer_height_m == 6.0
    for bad, where in (
        (b"unit: {class: hovercraft}\n", "class"),
        (b"unit: {max_slope_deg: 95}\n", "max_slope_deg"),
        (
            b"threats: [{position: [5, 5], sigma_range: 100, sigma_lateral: 50, observer_height_m: -1}]\n",
            "observer_height_m",
        ),
    ):
        with pytest.raises(InputError) as err:
            decode_scenario(head + bad, "yaml")
        assert where in str(err.value), err.value
