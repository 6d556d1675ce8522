"""A lone unit's A* with keep-out zones in force searches the very grid the whole-grid search builds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import ThreatField
from pfp_service.core.astar import lazy_route
from pfp_service.core.cores import SEARCH_FRACTION, Cores
from pfp_service.core.grid import GridGraph
from pfp_service.core.metrics import LAMBDA
from pfp_service.core.zones import Zone, ZoneSet
from tests.unit.test_astar_routes import BOX, random_field
from tests.unit.test_shared_routes import GOAL

pytestmark = pytest.mark.unit

ZONES = ZoneSet(
    [
        Zone.polygon("wall", [(20.0, -20.0), (24.0, -20.0), (24.0, 70.0), (20.0, 70.0)]),
        Zone.polygon(
            "sliver", [(60.0, 40.0), (60.4, 40.0), (60.4, 125.0), (60.0, 125.0)]
        ),  # thinner than a cell
        Zone.circle("pond", (90.0, 20.0), 12.0),
    ]
)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("cell", [1.0, 2.3])
def test_with_zones_a_star_finds_the_whole_grids_cheapest_path_and_enters_no_zone(
    seed: int, cell: float
) -> None:
    field = ThreatField(random_field(seed).threats, zones=ZONES)
    cores = Cores.of(field, SEARCH_FRACTION)
    grid = GridGraph(field, BOX, cores=cores, cell_m=cell)  # what the whole-grid search builds for this ask
    src, dst = grid.cell_of(0.0, 0.0), grid.cell_of(*GOAL)
    lazy = lazy_route(field, BOX, cores, cell, (0.0, 0.0), GOAL, LAMBDA, 8)
    if not (grid.open[src] and grid.open[dst]):
        assert lazy is None
        return
    dist, _ = grid.cost_to(dst, LAMBDA)
    if not math.isfinite(dist[src]):
        assert lazy is None
        return
    assert lazy is not None, seed
    assert lazy.nodes[0] == src and lazy.nodes[-1] == dst
    assert np.array_equal(lazy.points, grid.nodes[lazy.nodes])  # the grid's very nodes, to the bit
    if lazy.searches == 1:  # no edge repaired away: the cheapest path of the same graph
        assert lazy.cost == pytest.approx(float(dist[src]), rel=1e-9), (seed, cell)
    assert not cores.segment_hits(lazy.points).any()
    assert len(lazy.corners) == len(lazy.nodes)  # every node to the shortcut, as from the grid's walk
    assert 0 < lazy.expanded < len(grid.nodes)


def test_with_zones_a_unit_inside_one_is_left_to_the_whole_grid() -> None:
    field = ThreatField(random_field(1).threats, zones=ZONES)
    cores = Cores.of(field, SEARCH_FRACTION)
    assert lazy_route(field, BOX, cores, 1.0, (90.0, 20.0), GOAL, LAMBDA, 8) is None
    assert lazy_route(field, BOX, cores, 1.0, (0.0, 0.0), (90.0, 20.0), LAMBDA, 8) is None
