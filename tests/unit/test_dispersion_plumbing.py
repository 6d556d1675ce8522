"""Dispersion's per-tick plumbing: a few rows' neighbours are the fleet's, and a held direction goes on the wire.

``NeighbourIndex.near`` queries a tick's few rows on their own and many
through the fleet's pairs: both must give the same pairs.  A unit yielding
in a crowd is told to make room (``reach_m`` the pair's separation): the
direction must be plain floats, which the wire encodes (a NumPy scalar
failed the whole tick's publishing).
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.core.dispersion import FEW_ROWS, NeighbourIndex
from pfp_service.wire import Goal, UnitState, encode
from pfp_service.world.events import GoalSet, StateReported
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.world import World, WorldSettings

pytestmark = pytest.mark.unit


def _pairs(i: np.ndarray, j: np.ndarray) -> set[tuple[int, int]]:
    return set(zip(i.tolist(), j.tolist()))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_near_for_a_few_rows_is_the_fleets_pairs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 400, (200, 2))
    pts[7] = pts[8]  # two units on one point are still each other's neighbours
    seps = rng.choice([5.0, 50.0], 200)
    index = NeighbourIndex(pts, seps)
    rows = rng.choice(200, 200 // FEW_ROWS - 3, replace=False)
    rows = np.append(rows, [7, 7])  # a row twice counts once
    few = index.near(rows)
    i, j = index.pairs()
    keep = np.isin(i, rows)
    assert _pairs(*few) == _pairs(i[keep], j[keep])
    assert len(few[0]) == int(keep.sum())  # no pair twice
    assert not np.any(few[0] == few[1])
    some = rows[: len(rows) // 2]  # rows among the last query's take its pairs
    part = index.near(some)
    keep = np.isin(i, some)
    assert _pairs(*part) == _pairs(i[keep], j[keep]) and len(part[0]) == int(keep.sum())
    many = index.near(np.arange(200))  # the fleet's pairs, as before
    assert _pairs(*many) == _pairs(i, j)
    fresh = NeighbourIndex(pts, seps).near(some)  # the same pairs queried afresh, in the same order
    assert np.array_equal(fresh[0], part[0]) and np.array_equal(fresh[1], part[1])


def test_a_crowded_yield_encodes() -> None:
    rng = random.Random(3)
    w = World(WorldSettings(dispersion=DispersionSettings(enabled=True)))
    # 60 units in a 100 m x 2 km strip (vehicles keep 50 m), all driving east, one report a tick:
    # some yield in a crowd and are told to make room, a step nothing else cuts
    at = {f"u{k}": (rng.uniform(0, 100), rng.uniform(0, 2000)) for k in range(60)}
    w.apply([StateReported(u, UnitState(position=p)) for u, p in at.items()], 0.0)
    seen = list(w.apply([GoalSet(u, Goal(position=(2000.0, p[1]))) for u, p in at.items()], 0.0).directions)
    for t in range(1, 4):
        for u, p in at.items():
            seen += w.apply([StateReported(u, UnitState(position=p, speed_mps=1.0))], float(t)).directions
    assert any("making room" in d.reason and d.reach_m for d in seen)
    for d in seen:
        encode(d)  # plain floats throughout


def _yields(m1: tuple[float, float], m1_goal: tuple[float, float], r1_goal: tuple[float, float]) -> list[str]:
    """What unmanned ``r1`` at the origin is told over a few reports near manned ``m1`` (neither moves)."""
    from pfp_service.wire import Goal, UnitKind, UnitState
    from pfp_service.world import events as ev
    from pfp_service.world.separations import DispersionSettings
    from pfp_service.world.world import World, WorldSettings

    w = World(WorldSettings(deliberation="deferred", dispersion=DispersionSettings(enabled=True)))
    w.apply([ev.GoalSet("m1", Goal(position=m1_goal)), ev.GoalSet("r1", Goal(position=r1_goal))], 0.0)
    said = []
    for t in range(4):
        states = [
            ev.StateReported("m1", UnitState(position=m1, kind=UnitKind.MANNED)),
            ev.StateReported("r1", UnitState(position=(0.0, 0.0), kind=UnitKind.UNMANNED)),
        ]
        said += [d.reason for d in w.apply(states, float(t)).directions if d.unit == "r1"]
    return said


def test_right_of_way_is_for_paths_that_meet_not_for_neighbours_going_side_by_side() -> None:
    import numpy as np

    from pfp_service.world.deadlocks import meet as _meet

    # the other 60 m off ahead-left: (its way, one's own) -> whether their paths meet, separation 50 m
    cases = {
        ((1.0, 0.0), (1.0, 0.0)): False,  # side by side, one way: the gap holds
        ((0.0, -1.0), (1.0, 0.0)): True,  # it crosses one's way: they meet
        ((0.0, 1.0), (1.0, 0.0)): False,  # it draws away across: the paths pass wide
        ((-1.0, 0.0), (1.0, 0.0)): True,  # head on along lines 45 m apart: within the separation
        ((-1.0, 0.0), (0.0, -1.0)): False,  # it goes west as one goes south: the gap opens
    }
    rel = np.array([[40.0, 45.0]] * len(cases))
    closing = np.array([np.subtract(other, mine) for other, mine in cases], dtype=float)
    got = _meet(rel, closing, np.full(len(cases), 50.0)).tolist()
    assert got == list(cases.values())
    # in the world: m1 70 m ahead, head on, r1 yields to it
    assert any(r.startswith("yielding to m1") for r in _yields((0.0, 70.0), (0.0, -600.0), (0.0, 600.0)))
