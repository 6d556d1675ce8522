"""The wide warm-up: a big tick run once before serving, so that no numba kernel compiles in the live loop.

``previews.warm_up`` runs the small cases (one threat, none, a keep-out zone);
``warm_wide`` runs what only a big world reaches, each through the path the
live loop takes:

* ``MIN_THREATS`` threats and more: the culled kernels (``cull._culled_descent``,
  ``cull._fill``, ``cull.point_level``, ``cull._cell_level``) and a zone's
  step rule among them (``steprule.judge_zoned``, called from Python too by
  ``Stepper.follow``);
* two units trapped in a cup of keep-out zone with one goal: the second
  builds the shared route grid (``grid._edges``, ``cores._raster``);
* a route shortened among those threats with no zone in force, as a route
  search over open ground does: the compiled ``polylines._shortcut_kept``
  (the cup's zone sends its routes down the numpy path instead);
* the same kernels past ``kernels.PARALLEL_MIN_PAIRS`` (a storm's tick):
  ``cull._culled_descent_parallel``, ``cull._predict_parallel``,
  ``kernels.batch_descent``, and past ``PARALLEL_MIN_PAIRS_LEVEL``
  ``kernels._parallel_level``;
* a team's follower stepping out of its corridor: ``polyline_kernels.project_shared``
  (``project`` and ``shared`` in one call), ``project`` and ``kept``; its lead making for its
  place: ``places``, and ``place`` for one; its lead's track grown by a point: ``extend_one``;
* six units crowding each other with dispersion on: the tick's neighbour passes
  (``core.neighbour_kernels``) and the cut of their ways at each other's discs
  (``core.keep_apart_kernels.cut``); a back-off cut to nothing turning to a free
  way (``keep_apart_kernels.entries``);
* a threat over terrain (a synthetic hill): the viewshed sweep
  (``terrain.viewshed._sweep``) and every kernel on rows that carry a
  visibility window.

A kernel loads from numba's cache in milliseconds, or compiles in seconds
on a fresh checkout: either way here, not in the loop.
``tests/proc/test_warmup.py`` runs a bigger tick after this, in a fresh
interpreter, and fails if any kernel gained a signature.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Iterator

import numpy as np

from pfp_service.core import PlannerParams, Stepper, Threat, ThreatField, kernels, resolve
from pfp_service.core.cull import MIN_THREATS, CullIndex, cell_level, predict
from pfp_service.core.zones import ZoneSet
from pfp_service.wire import Goal, ThreatUpdate, UnitState
from pfp_service.wire.messages import ZoneUpdate
from pfp_service.world.events import GoalSet, Input, StateReported, ThreatPut, Tick, WorldSettings, ZonePut

__all__ = ["forget_warm_worlds", "warm_wide"]

CROWD_THREATS = MIN_THREATS + 8


def warm_wide(base: WorldSettings, terrain: bool = True) -> None:
    """Run the big tick's kernels once (``base``'s planner parameters, deliberation inline, no bounds); the
    terrain's with ``terrain``."""
    from pfp_service.world.world import World

    settings = dataclasses.replace(base, deliberation="inline", bounds=None, terrain=None)
    world = World(settings)
    with _tight_routes():
        world.apply(_crowd(), 0.0)
        for k in range(1, 4):  # the trapped pair moves a little: their routes are walked, and shared
            world.apply(
                [StateReported(f"c{i}", UnitState(position=(0.01 * k, 2.0 * i - 1.0))) for i in (0, 1)], k
            )
    _parallel(world.field.packed, world.field.zones)
    _binned()
    _shortcut(world.field.threats)
    # a batch's unit in plain descent among zones, its gradient given (``advise_many``): judged from Python
    lone = Stepper((0.0, 0.0), (100.0, 0.0), resolve(PlannerParams(), (0.0, 0.0), (100.0, 0.0)), None, 0)
    lone.follow(-30.0, 0.0, 1.0, 0.0, 0.0, 1.0, world.field)
    _team()
    _dispersion(settings)
    if terrain:
        _terrain(settings)


@contextlib.contextmanager
def _tight_routes() -> Iterator[None]:
    """The shared route cache without room round a shared goal's grid while the warm-up's crowd searches.

    The kernels are the same on a tight grid (``grid._edges``, ``cores._raster``); the room and the finer
    cell of a shared goal's grid (``routes.RouteCache._shape``) made the crowd's 63,210 nodes, 20 MB held
    while the warm-up ran and the process's peak with them.  Tight, its grid holds 5,656 nodes (1.8 MB).
    A planner's own searches run in its deliberation workers, which share goals with room as before; a
    process warms before it plans, so no search of its own sees the room at nothing.
    """
    from pfp_service.core.routes import ROUTES

    room, ROUTES.room = ROUTES.room, 0.0
    try:
        yield
    finally:
        ROUTES.room = room


def forget_warm_worlds() -> None:
    """Drop what the warm-up's throwaway worlds left behind, and hand the freed heap back to the system.

    Their route searches stay in the process-wide ``core.routes.ROUTES`` (a gone field's grid is
    dropped only at the cache's next insert, which a planner's loop never makes: its searches run
    in the workers), and every worker forked from this process would inherit them.  Measured in
    process (BENCHMARKS.md, "The warm-up's worlds forgotten"): the heap after both warm-ups fell
    from 102 MB to 47 MB, 24 MB of it two grids and the rest freed pages glibc kept.
    """
    import ctypes
    import gc

    from pfp_service.core.routes import ROUTES

    ROUTES.clear()
    gc.collect()
    with contextlib.suppress(OSError, AttributeError):  # glibc only; elsewhere the heap stays as it is
        ctypes.CDLL(None).malloc_trim(0)


def _team() -> None:
    """A follower's step leaving its corridor at a bend, and a lead making for its place: the compiled
    walks of a team's polylines (``core.polyline_kernels``: projection, shared stadium and the two in one
    call, capsule run, the leads' places, a track grown in place), which only teams reach."""
    from pfp_service.world import team_lines, teams

    teams.follow((5.0, 0.0), (15.0, 5.0), [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)], 4.0, "lead", "")
    teams.lead((0.0, 1.0), [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)], 5.0, "main")
    one_route = np.array([(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)])  # a route as an array: ``place``
    teams.lead((0.0, 1.0), one_route, 5.0, "main")
    # a lead's track grown by a point for its followers (``team_lines``): ``extend_one``
    team_lines.grow(None, teams.Polyline([(0.0, 0.0), (10.0, 0.0)]), [(10.0, 10.0)])


def _dispersion(settings: WorldSettings) -> None:
    """Six units within each other's separation, crossing, with dispersion on, then one of them moving: the
    tick's compiled neighbour passes (``core.neighbour_kernels``: the pairs' separations and push terms,
    right of way's first look, a kept tree's moved rows) and its cut (``core.keep_apart_kernels.cut``),
    which only dispersion reaches; and a back-off cut to nothing turned to a free way
    (``keep_apart.free_way``: ``keep_apart_kernels.entries``), which the six do not reach."""
    from pfp_service.core.dispersion import NeighbourIndex
    from pfp_service.world import keep_apart
    from pfp_service.world.separations import DispersionSettings
    from pfp_service.world.world import World

    world = World(dataclasses.replace(settings, dispersion=DispersionSettings(enabled=True)))
    inputs: list[Input] = []
    for i in range(6):
        inputs.append(StateReported(f"d{i}", UnitState(position=(10.0 * i, 0.0))))
        inputs.append(GoalSet(f"d{i}", Goal(position=(50.0 - 10.0 * i, 5.0))))
    world.apply(inputs, 0.0)
    for k in range(1, 4):  # one unit's small move a tick: the kept tree, asked again at the row that moved
        world.apply([StateReported("d0", UnitState(position=(0.5 * k, 0.1 * k)))], float(k))
    facing = NeighbourIndex(np.array([(0.0, 0.0), (0.0, 10.0)]), np.full(2, 10.0))
    keep_apart.free_way(facing, 0, (0.0, 1.0), np.array([0.0, -1.0]), 10.0)


def _crowd() -> list[Input]:
    """Threats on a ring far off, a cup of zone round two units whose goal lies past its bottom.

    The threats' sigmas set the route grid's cell: at 24 / 16 m it holds 5,656 nodes searched tight
    (``_tight_routes``; 63,210 with a shared goal's room, 77,106 at 6 / 4 m), the same kernels for a smaller
    peak while the warm-up runs."""
    inputs: list[Input] = []
    for j in range(CROWD_THREATS):
        a = 2.0 * math.pi * j / CROWD_THREATS
        where = (60.0 + 200.0 * math.cos(a), 200.0 * math.sin(a))
        inputs.append(ThreatPut(f"w{j}", ThreatUpdate(position=where, sigma_range=24.0, sigma_lateral=16.0)))
    cup = [(-20.0, 20.0), (20.0, 20.0), (20.0, -20.0), (-20.0, -20.0), (-20.0, -18.0)]
    cup += [(18.0, -18.0), (18.0, 18.0), (-20.0, 18.0), (-20.0, 20.0)]
    inputs.append(ZonePut("cup", ZoneUpdate(polygon=[cup])))
    for i in (0, 1):
        inputs.append(StateReported(f"c{i}", UnitState(position=(0.0, 2.0 * i - 1.0))))
        inputs.append(GoalSet(f"c{i}", Goal(position=(100.0, 0.0))))
    return inputs


def _shortcut(threats: tuple[Threat, ...]) -> None:
    """A path shortened over ``threats`` (a cull index, no zone): ``polylines._shortcut_kept``."""
    from pfp_service.core.polylines import shortcut_kept

    path = np.column_stack([np.linspace(-50.0, 150.0, 9), np.linspace(0.0, 20.0, 9) ** 0.5])
    shortcut_kept(ThreatField(threats), np.ascontiguousarray(path), 1.0, None)


def _parallel(packed: np.ndarray, zones: ZoneSet) -> None:
    """The descent, look-ahead (among zones and none) and level kernels, serial and past their parallel
    thresholds."""
    rng = np.random.default_rng(0)
    n = kernels.PARALLEL_MIN_PAIRS  # pairs >= points, whatever the threats
    pts = np.ascontiguousarray(rng.uniform(-200.0, 300.0, (n, 2)))
    goals = np.ascontiguousarray(np.tile([100.0, 0.0], (n, 1)))
    gains = np.ones(n)
    out = np.empty((n, 4))
    kernels.descent_many(packed, pts, goals, gains, out)
    index = CullIndex(packed)
    index.descent(pts, goals, gains, out)
    cell_level(index, pts[:64])
    stepper = Stepper(
        (0.0, 0.0), (100.0, 0.0), resolve(PlannerParams(), (0.0, 0.0), (100.0, 0.0), []), None, 0
    )
    units = np.tile(stepper.rules(), (n // 4, 1))
    for idx in (index, None):
        for among in (zones, None):
            for m in (n // 4, 2):
                predict(packed, idx, pts[:m], units[:m], 4, among)
    big = max(1, math.ceil(kernels.PARALLEL_MIN_PAIRS_LEVEL / max(packed.shape[0], 1)))
    kernels.batch_level(packed, np.ascontiguousarray(rng.uniform(-200.0, 300.0, (big, 2))), np.empty(big))


def _binned() -> None:
    """A zone set as large as a terrain's slope barriers, asked which points lie near it (``zone_bins``)."""
    from pfp_service.core.zone_bins import BINNED_FROM
    from pfp_service.core.zones import Zone

    zones = ZoneSet(
        Zone.polygon(f"w{k}", [(10.0 * k, 0.0), (10.0 * k + 5.0, 0.0), (10.0 * k + 5.0, 5.0)])
        for k in range(BINNED_FROM)
    )
    zones.contains(np.array([[2.0, 1.0], [math.nan, 0.0], [500.0, 500.0]]), 1.0)


def _terrain(settings: WorldSettings) -> None:
    """A threat on a hill over a small grid, a unit guided past it: the sweep and the masked rows."""
    from pfp_service.terrain.grid import TerrainGrid
    from pfp_service.terrain.live import of_grid
    from pfp_service.world.world import World

    xs = np.arange(41) * 10.0 - 200.0
    gx, gy = np.meshgrid(xs, xs)
    hill = 100.0 + 30.0 * np.exp(-(gx**2 + gy**2) / (2 * 60.0**2))
    ground = of_grid(TerrainGrid(-200.0, -200.0, 10.0, hill))
    world = World(dataclasses.replace(settings, terrain=ground, bounds=ground.bounds))
    world.apply(
        [
            ThreatPut("h", ThreatUpdate(position=(0.0, 0.0), sigma_range=60.0, sigma_lateral=40.0)),
            StateReported("g", UnitState(position=(-150.0, -150.0))),
            GoalSet("g", Goal(position=(150.0, 150.0))),
            Tick(1.0),
        ],
        0.0,
    )
