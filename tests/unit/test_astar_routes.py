"""A lone unit's route by lazy A* (``core.astar``) is a cheapest path of the very grid Dijkstra searches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import Threat, ThreatField
from pfp_service.core.astar import cell_ladder, clear_lattices, lazy_route
from pfp_service.core.cores import SEARCH_FRACTION, Cores
from pfp_service.core.escape_strategies import global_route
from pfp_service.core.grid import GridGraph
from pfp_service.core.metrics import LAMBDA
from pfp_service.core.routes import RouteCache
from tests.unit.test_shared_routes import GOAL, platoon, trap_rich, traps

pytestmark = pytest.mark.unit

BOX = ((-30.0, -30.0), (140.0, 130.0))


def random_field(seed: int, n: int = 30) -> ThreatField:
    rng = np.random.default_rng(seed)
    threats = []
    for k in range(n):
        x, y = rng.uniform(0.0, 110.0, 2)
        if min(math.dist((x, y), (0.0, 0.0)), math.dist((x, y), GOAL)) < 15.0:
            continue
        sr, sl = rng.uniform(2.0, 8.0, 2)
        threats.append(
            Threat.from_facing((float(x), float(y)), float(rng.uniform(0, 360)), sr, sl, 1.0, 1.0, f"t{k}")
        )
    return ThreatField(threats)


def snapped(box, cell):  # the lattice lazy_route searches for this box and cell, as a GridGraph box
    _, h = cell_ladder(cell)
    (x0, y0), (x1, y1) = box
    i0, k0 = math.ceil(x0 / h), math.ceil(y0 / h)
    return ((i0 * h, k0 * h), (math.floor(x1 / h) * h, math.floor(y1 / h) * h)), h


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("cell", [1.0, 2.5])
def test_lazy_a_star_costs_what_dijkstra_on_the_whole_grid_costs(seed: int, cell: float) -> None:
    field = random_field(seed)
    cores = Cores.of(field, SEARCH_FRACTION)
    box, h = snapped(BOX, cell)
    assert h <= cell and h > cell / 1.1  # the ladder's rung at or just under the asked cell
    grid = GridGraph(field, box, cores=cores, cell_m=h)
    src, dst = grid.cell_of(0.0, 0.0), grid.cell_of(*GOAL)
    clear_lattices()
    lazy = lazy_route(field, BOX, cores, cell, (0.0, 0.0), GOAL, LAMBDA, 0)
    if not (grid.open[src] and grid.open[dst]):
        assert lazy is None
        return
    dist, _ = grid.cost_to(dst, LAMBDA)
    if not math.isfinite(dist[src]):
        assert lazy is None  # no path: the caller builds the grid to say who is walled in
        return
    assert lazy is not None, seed
    assert lazy.cost == pytest.approx(float(dist[src]), rel=1e-9), (seed, cell)
    # it is a path of the grid: consecutive nodes are king or knight moves, from the unit's node to the goal's
    assert lazy.nodes[0] == src and lazy.nodes[-1] == dst
    ij = np.stack([lazy.nodes // grid.ny, lazy.nodes % grid.ny], axis=1)
    steps = {tuple(sorted(map(abs, d))) for d in np.diff(ij, axis=0).tolist()}
    assert steps <= {(0, 1), (1, 1), (1, 2)}
    assert np.allclose(lazy.points, grid.nodes[lazy.nodes], rtol=0, atol=1e-9)
    # and it touched less than the whole grid
    assert 0 < lazy.expanded < len(grid.nodes)
    # its corners: first and last, and between two corners one straight run of equal steps
    c = lazy.corners
    assert c[0] == 0 and c[-1] == len(lazy.nodes) - 1 and np.all(np.diff(c) > 0)
    d = np.diff(ij, axis=0)
    for a, b in zip(c[:-1], c[1:]):
        assert (d[a:b] == d[a]).all()
    assert all((d[k] != d[k - 1]).any() for k in c[1:-1])
    # a second search under the field reads the kept lattice: the same answer
    again = lazy_route(field, BOX, cores, cell, (0.0, 0.0), GOAL, LAMBDA, 0)
    assert again is not None and again.cost == lazy.cost and np.array_equal(again.nodes, lazy.nodes)
    # and after a search over another box first (the lattice grown, filled elsewhere): the same answer
    clear_lattices()
    lazy_route(field, ((40.0, -60.0), (200.0, 60.0)), cores, cell, (50.0, 0.0), (150.0, 0.0), LAMBDA, 0)
    third = lazy_route(field, BOX, cores, cell, (0.0, 0.0), GOAL, LAMBDA, 0)
    assert third is not None and third.cost == lazy.cost and np.array_equal(third.nodes, lazy.nodes)


def test_lazy_a_star_leaves_a_unit_in_a_core_to_the_whole_grid() -> None:
    field = random_field(1)
    cores = Cores.of(field, SEARCH_FRACTION)
    grid = GridGraph(field, BOX, cores=cores, cell_m=1.0)  # 1 m is on the ladder, BOX on its lattice
    shut = grid.nodes[np.flatnonzero(~grid.open)[0]]
    assert lazy_route(field, BOX, cores, 1.0, (float(shut[0]), float(shut[1])), GOAL, LAMBDA, 0) is None
    assert lazy_route(field, BOX, cores, 1.0, (0.0, 0.0), (float(shut[0]), float(shut[1])), LAMBDA, 0) is None


def test_a_lone_units_route_comes_from_a_star_and_matches_the_whole_grids_cost() -> None:
    field = ThreatField(trap_rich())
    (tr,) = traps(field, platoon(1))
    cache = RouteCache()
    got = global_route(tr, cache)
    assert isinstance(got, np.ndarray) and len(got) > 2
    st = cache.stats()
    assert st.lazy == 1 and st.entries == 0 and st.expanded > 0
    whole = RouteCache(max_entries=0)  # the same ask with A* unable to answer: a goal shared ...
    whole._shared[(tr.goal, LAMBDA, tr.bounds, SEARCH_FRACTION)] = None  # ... is searched on the whole grid
    ref = global_route(tr, whole)
    assert isinstance(ref, np.ndarray) and whole.stats().lazy == 0
    from pfp_service.core.metrics import path_cost

    assert path_cost(got, field) == pytest.approx(path_cost(ref, field), rel=0.01)


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_shortcut_keeps_what_the_whole_window_evaluation_keeps(seed: int) -> None:
    from pfp_service.core.polylines import _shortcut_kept_numpy, shortcut_kept

    field = random_field(seed, 60)
    cores = Cores.of(field, SEARCH_FRACTION)
    rng = np.random.default_rng(seed)
    pts = np.cumsum(rng.normal(1.5, 1.0, (90, 2)), axis=0)
    for c in (cores, None):
        got = shortcut_kept(field, pts, LAMBDA, c)
        assert np.array_equal(got, _shortcut_kept_numpy(field, pts, LAMBDA, c)), seed
        assert got[0] == 0 and got[-1] == len(pts) - 1


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_core_checks_answer_what_the_cores_answer(seed: int) -> None:
    from pfp_service.core.polylines import polyline_clear, segment_hits

    field = random_field(seed, 60)
    rng = np.random.default_rng(seed + 100)
    for fraction in (SEARCH_FRACTION, 0.5):
        cores = Cores.of(field, fraction)
        for steps in (rng.normal(1.5, 1.0, (60, 2)), rng.normal(0.3, 0.2, (200, 2))):
            pts = np.cumsum(steps, axis=0)
            assert np.array_equal(segment_hits(cores, pts), cores.segment_hits(pts)), seed
            for k in range(0, len(pts) - 3, 7):  # pieces that miss and pieces that hit
                piece = pts[k : k + 4]
                assert polyline_clear(cores, piece) == (not cores.first_hit(piece)), (seed, k)


def test_a_search_past_every_lattices_cap_goes_to_the_whole_grid_instead_of_writing_outside_one() -> None:
    """A box whose lattice no kept or fresh ``_Lattice`` may hold: ``None`` (the whole grid's search).

    It once ran A* on a lattice that did not cover the box: its compiled fill wrote past the arrays
    (heap corruption: 'double free or corruption' at exit, an LLVM assertion in another test).
    """
    field = random_field(3)
    cores = Cores.of(field, SEARCH_FRACTION)
    clear_lattices()
    huge = ((-600.0, -600.0), (700.0, 700.0))  # 1,300 x 1,300 nodes at 1 m, far past _MAX_POINTS
    assert lazy_route(field, huge, cores, 1.0, (0.0, 0.0), GOAL, LAMBDA, 0) is None
    assert (
        lazy_route(field, BOX, cores, 1.0, (0.0, 0.0), GOAL, LAMBDA, 0) is not None
    )  # and a fitting box still
