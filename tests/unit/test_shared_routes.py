"""Units that share a goal share its route search (``routes.RouteCache``), and get routes as good as their own."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Threat, ThreatField, resolve
from pfp_service.core.cores import SEARCH_FRACTION, Cores
from pfp_service.core.escape import Escaper
from pfp_service.core.escape_strategies import NoCandidate, Trap, global_route, route_cell
from pfp_service.core.grid import GridGraph
from pfp_service.core.metrics import LAMBDA, path_cost
from pfp_service.core.polylines import resample, shortcut
from pfp_service.core.routes import ROUTES, RouteCache
from pfp_service.core.stepper import Stepper, StepStatus

pytestmark = pytest.mark.unit

START, GOAL = (0.0, 0.0), (100.0, 100.0)
SEED = 20261201
TOLERANCE = 0.03  # a shared route may cost this much more J than the unit's own search


def trap_rich_specs(seed: int = SEED) -> list[tuple[tuple[float, float], float, float, float, float]]:
    """``(position, facing_deg, sigma_range, sigma_lateral, skew)``: a horseshoe open towards the start,
    its back to the goal, among seeded threats off the start and the goal."""
    out = []
    for k in range(9):
        b = math.radians(-55 + 200 * k / 8)
        out.append(((60 + 12 * math.sin(b), 60 + 12 * math.cos(b)), 225.0, 4.0, 4.0, 0.5))
    rng = np.random.default_rng(seed)
    while len(out) < 24:
        x, y = rng.uniform(10.0, 110.0, 2)
        if min(math.dist((x, y), START), math.dist((x, y), GOAL), math.dist((x, y), (60, 60))) > 22.0:
            out.append(((float(x), float(y)), float(rng.uniform(0, 360)), 4.0, 3.0, 1.0))
    return out


def trap_rich(seed: int = SEED) -> list[Threat]:
    return [Threat.from_facing(*spec, 1.0, f"t{k}") for k, spec in enumerate(trap_rich_specs(seed))]


def platoon(n: int, seed: int = SEED, spread_m: float = 8.0) -> list[tuple[float, float]]:
    """``n`` units within ``spread_m`` of the start (the trip is 141 m)."""
    rng = np.random.default_rng(seed + 1)
    return [(float(x), float(y)) for x, y in START + rng.uniform(-spread_m, spread_m, (n, 2))]


def traps(field: ThreatField, units: list[tuple[float, float]], goal=GOAL) -> list[Trap]:
    params = resolve(PlannerParams(escape="auto"), START, goal, list(field.threats))
    out = []
    for key, (x, y) in enumerate(units, start=1):
        esc = Escaper(params, goal, params.delta / math.dist((x, y), goal) ** 2, None, unit_key=key)
        out.append(esc._trap(field, x, y))
    return out


def routes(trs: list[Trap], cache: RouteCache) -> list[np.ndarray]:
    found = [global_route(tr, cache) for tr in trs]
    assert not any(isinstance(p, NoCandidate) for p in found), found
    return found  # type: ignore[return-value]


def test_a_platoon_walks_one_search_and_each_route_is_as_good_as_its_own():
    field = ThreatField(trap_rich())
    units = platoon(24)
    own = RouteCache(max_entries=0)  # one search per unit: what every unit did before
    mine = routes(traps(field, units), own)
    assert own.stats().searches == len(units)
    shared = RouteCache()
    ours = routes(traps(field, units), shared)
    st = shared.stats()
    # first sight of the goal: the first unit's own search, then one for the group
    assert st.searches == 2, (SEED, st)
    assert st.hits == len(units) - 2
    cores = Cores.of(field)
    for k, (a, b) in enumerate(zip(mine, ours)):
        assert math.dist(b[0], units[k]) == 0.0 and math.dist(b[-1], GOAL) == 0.0
        assert not cores.first_hit(b), (SEED, k)
        assert path_cost(b, field) <= (1.0 + TOLERANCE) * path_cost(a, field), (SEED, k)
    # the world changes: the goal is known to be shared, so one search serves the platoon
    moved = ThreatField(trap_rich())
    before = shared.stats().searches
    again = routes(traps(moved, units), shared)
    assert shared.stats().searches - before == 1
    for k, b in enumerate(again):
        assert path_cost(b, moved) <= (1.0 + TOLERANCE) * path_cost(mine[k], field), (SEED, k)


def test_a_lone_unit_gets_a_route_as_good_as_its_own_whole_grid_search_gave():
    field = ThreatField(trap_rich())
    (tr,) = traps(field, platoon(1))
    got = global_route(tr, RouteCache())
    # the search as it was before routes.py: one grid around the unit and the goal
    s_min = tr.cores.min_spread_m
    pad = max(0.3 * tr.dist, 3.0 * max(t.spread() for t in field.threats))
    box = (
        (min(tr.x, GOAL[0]) - pad, min(tr.y, GOAL[1]) - pad),
        (max(tr.x, GOAL[0]) + pad, max(tr.y, GOAL[1]) + pad),
    )
    span = max(box[1][0] - box[0][0], box[1][1] - box[0][1])
    search = Cores.of(field, SEARCH_FRACTION)
    grid = GridGraph(field, box, cores=search, cell_m=route_cell(span, s_min, fine=False))
    route = grid.route(grid.nearest(tr.x, tr.y), grid.nearest(*GOAL), LAMBDA)
    assert len(route.points)
    pts = np.concatenate([[[tr.x, tr.y]], route.points, [GOAL]])
    pts = pts[np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)])]
    want = resample(shortcut(field, pts, LAMBDA, search), tr.step)
    # A* searches the field's lattice at the ladder's cell at or just under this one (astar.cell_ladder)
    assert isinstance(got, np.ndarray)
    assert path_cost(got, field) <= (1.0 + TOLERANCE) * path_cost(want, field), SEED
    assert not search.first_hit(got) and np.array_equal(got[-1], GOAL)


def test_a_new_field_never_uses_an_old_fields_search():
    threats = trap_rich()
    units = platoon(6)
    cache = RouteCache()
    first = routes(traps(ThreatField(threats), units), cache)
    # a threat put across the platoon's way: the same goal, a new world version
    mid = first[0][len(first[0]) // 2]
    blocker = Threat.from_facing(tuple(mid), 0, 4.0, 4.0, 0.0, 1.0, "blocker")
    field = ThreatField([*threats, blocker])
    before = cache.stats()
    after = routes(traps(field, units), cache)
    st = cache.stats()
    assert st.misses > before.misses and st.searches > before.searches
    cores = Cores.of(field)
    for k, poly in enumerate(after):
        assert not cores.first_hit(poly), k  # routed round the new threat's core
        assert not np.array_equal(poly, first[k])


def test_the_bounds_on_grids_and_nodes_hold():
    field = ThreatField(trap_rich())
    goals = [(100.0, 100.0), (110.0, 40.0), (40.0, 110.0), (90.0, 70.0), (70.0, 95.0), (105.0, 85.0)]
    pair = platoon(3)
    cache = RouteCache(max_entries=3)
    for goal in goals:  # two units each: the first one's own search, then the pair's, which is kept
        routes(traps(field, pair[:2], goal), cache)
        assert cache.stats().entries <= 3
    st = cache.stats()
    assert st.entries == 3 and st.evictions == len(goals) - 3 and st.searches == 2 * len(goals)
    # the oldest goal went first: a third unit for it searches again (once: it is known shared),
    # a third unit for the newest does not
    routes(traps(field, pair, goals[-1])[2:], cache)
    assert cache.stats().searches == 2 * len(goals)
    routes(traps(field, pair, goals[0])[2:], cache)
    assert cache.stats().searches == 2 * len(goals) + 1
    # a lone unit's search is used once and never kept
    lone = RouteCache()
    routes(traps(field, pair[:1], (95.0, 95.0)), lone)
    assert lone.stats().entries == 0 and lone.stats().searches == 1
    # nodes: without room each grid here has about 22,500; a bound of 50,000 keeps two at most
    small = RouteCache(max_nodes=50_000, room=0.0)
    for goal in goals:
        routes(traps(field, pair[:2], goal), small)
        assert small.stats().nodes <= 50_000
    assert small.stats().entries == 2


def test_threads_sharing_a_cache_behind_their_own_lock_pay_one_search():
    # the cache takes no lock (the core does no concurrency): whoever shares it between threads holds one
    field = ThreatField(trap_rich())
    trs = traps(field, platoon(16))
    cache = RouteCache()
    global_route(trs[0], cache)  # the first unit's own; the goal is not known to be shared yet
    out: list[object] = [None] * len(trs)
    start = threading.Barrier(4)
    owner = threading.Lock()

    def worker(k0: int) -> None:
        start.wait()
        for k in range(k0, len(trs), 4):
            with owner:
                out[k] = global_route(trs[k], cache)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert all(isinstance(p, np.ndarray) for p in out)
    assert cache.stats().searches == 2  # the first unit's own, then one for the rest


@pytest.mark.parametrize("n", [8])
def test_steppers_of_a_platoon_foresee_through_the_process_cache(n):
    field = ThreatField(trap_rich())
    params = resolve(PlannerParams(escape="auto"), START, GOAL, list(field.threats))
    before = ROUTES.stats()
    going_round = 0
    for key, (x, y) in enumerate(platoon(n), start=100):
        adv = Stepper((x, y), GOAL, params, None, key).advise(field, x, y)
        going_round += adv.status is StepStatus.ESCAPING
    st = ROUTES.stats()
    assert going_round >= n // 2  # the horseshoe is foreseen and gone round
    assert st.searches - before.searches <= 2 and st.hits - before.hits >= going_round - 2


def test_nearest_open_node_is_the_nearest_of_all_open_nodes():
    field = ThreatField(trap_rich())
    rng = np.random.default_rng(SEED)
    for cell in (0.7, 2.3):
        grid = GridGraph(field, ((-10.0, -10.0), (130.0, 120.0)), cores=Cores.of(field, 0.05), cell_m=cell)
        opened, closed = np.flatnonzero(grid.open), np.flatnonzero(~grid.open)
        assert len(closed) > 100
        probes = grid.nodes[rng.choice(closed, 400)] + rng.uniform(-cell, cell, (400, 2))
        probes = np.concatenate([probes, rng.uniform(-40.0, 160.0, (100, 2))])  # and outside the box
        for x, y in probes:
            d = np.hypot(grid.nodes[opened, 0] - x, grid.nodes[opened, 1] - y)
            assert grid.nearest(x, y) == opened[int(np.argmin(d))], (SEED, cell, x, y)


def test_a_platoons_deliberation_jobs_in_the_world_share_one_route_search():
    from pfp_service.wire import Goal, ThreatUpdate, UnitState
    from pfp_service.world.world import GoalSet, Input, StateReported, ThreatPut, World, WorldSettings

    world = World(WorldSettings(planner=PlannerParams(), deliberation="deferred", unit_forget_s=None))
    puts: list[Input] = [
        ThreatPut(f"t{k}", ThreatUpdate(position=p, facing_deg=f, sigma_range=sr, sigma_lateral=sl, skew=a))
        for k, (p, f, sr, sl, a) in enumerate(trap_rich_specs())
    ]
    world.apply(puts, 0.0)
    units = platoon(20)
    first: list[Input] = [StateReported(f"u{k}", UnitState(position=p, seq=0)) for k, p in enumerate(units)]
    first += [GoalSet(f"u{k}", Goal(position=GOAL)) for k in range(len(units))]
    out = world.apply(first, 1.0)
    assert len(out.jobs) == len(units)
    before = ROUTES.stats()
    for job in out.jobs:
        job.run()
    st = ROUTES.stats()
    asks = st.hits + st.misses - before.hits - before.misses
    assert asks >= len(units) // 2  # most foresee the horseshoe, or a dear descent, and ask for a route
    assert st.searches - before.searches <= 2, (asks, st)
