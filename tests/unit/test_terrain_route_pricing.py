"""Route searches price a masked field as the unit walks it (issue 32): shortcut samples, route cells, J ties.

A masked level steps from hidden to seen over a visibility window's cell, so
whatever prices a line under it must sample at that scale; and where two ways
tie on ``J`` within the pricing's error, the less exposed one is taken.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Threat, ThreatField, plan
from pfp_service.core.metrics import LAMBDA, path_cost
from pfp_service.core.mobility import CLASSES
from pfp_service.core.polylines import resample, sample_spacing, segment_costs
from pfp_service.core.routes import route_cell
from pfp_service.core.visibility import finest_cell
from pfp_service.core.zones import ZoneSet
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.threat_sight import TerrainSight

pytestmark = pytest.mark.unit

FOOT = CLASSES["foot"]


def _corrugated(half_m: float = 3000.0, cell_m: float = 40.0) -> TerrainGrid:
    """Walls 40 m high every 400 m along x: from a tower, only a strip in front of each wall is seen."""
    xs = np.arange(-half_m, half_m + cell_m / 2, cell_m)
    gx, _ = np.meshgrid(xs, xs)
    z = np.where(np.mod(gx, 400.0) < 80.0, 40.0, 0.0)
    return TerrainGrid(-half_m, -half_m, cell_m, z)


TOWER = Threat.from_facing((-2900.0, 0.0), 90.0, 3000.0, 3000.0, 0.0, 1.0, "tower", observer_height_m=60.0)


def test_the_finest_cell_is_the_narrowest_window_and_none_without_sight() -> None:
    grid = _corrugated()
    assert finest_cell(ThreatField([TOWER]).packed) == math.inf
    seen = ThreatField([TOWER], sight=TerrainSight(grid, FOOT.height_m))
    assert finest_cell(seen.packed) == pytest.approx(40.0)
    assert sample_spacing(seen) == pytest.approx(40.0)
    assert route_cell(8000.0, 500.0, False, 40.0) < route_cell(8000.0, 500.0, False)


def test_a_long_segment_is_priced_as_the_unit_walks_it_over_a_masked_field() -> None:
    field = ThreatField([TOWER], sight=TerrainSight(_corrugated(), FOOT.height_m))
    a, b = np.array([[-2500.0, 100.0]]), np.array([[2500.0, 100.0]])
    walked = path_cost(resample(np.concatenate([a, b]), 5.0), field, LAMBDA)  # the truth, every 5 m
    priced = float(segment_costs(field, a, b, LAMBDA)[0])
    fixed = float(segment_costs(field, a, b, LAMBDA, math.inf)[0])  # 17 samples, 312 m apart
    exposure = (walked - 5000.0) / LAMBDA
    print(
        f"exposure walked {exposure:.0f}, priced {(priced - 5000.0) / LAMBDA:.0f}, on 17 samples {(fixed - 5000.0) / LAMBDA:.0f}"
    )
    assert exposure > 100.0  # the strips are seen
    assert abs(priced - walked) <= 0.1 * LAMBDA * exposure
    assert abs(fixed - walked) > 0.2 * LAMBDA * exposure  # what a fixed count of samples got wrong


@pytest.fixture(scope="module")
def jacksboro(tmp_path_factory: pytest.TempPathFactory) -> str:
    from tests import terrain_data

    return str(terrain_data.write_geographic(tmp_path_factory.mktemp("dem") / "jacksboro.tif"))


@pytest.mark.parametrize("seed", [3, 7, 11, 19])
def test_over_terrain_the_plan_is_never_more_exposed_than_the_blind_one(jacksboro: str, seed: int) -> None:
    """The seeds where it was (pfp bench terrain_routes): 3 took a gap in view tied on J with a hidden way."""
    from pfp_service.terrain.planning import prepare
    from tests.terrain_scenarios import scenario

    base = prepare(jacksboro, None, [(-5000.0, -5000.0), (5000.0, 5000.0)], None, FOOT)
    start, goal, sched = scenario(base.grid, seed)
    g = prepare(jacksboro, None, [start, goal, *(s.threat.xi for s in sched)], None, FOOT)
    over = plan(start, goal, sched, PlannerParams(), g.bounds, zones=ZoneSet(g.zones), sight=g.sight)
    blind = plan(start, goal, sched, PlannerParams(), g.bounds)
    print(f"seed {seed}: masked {over.exposure:.2f}, blind {blind.exposure:.2f}")
    assert over.status.value == "reached", over.reason
    assert over.exposure <= blind.exposure
