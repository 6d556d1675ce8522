"""A unit found stuck is stuck against the unit at rest whose disc stopped it (issue 33, gaps seed 2).

With the cut moving a neighbour going the unit's way and a pushed descent never turning back (issue
33's rules 1 and 2), seed 2's ``u0102`` and ``u0105`` stood from 885 s until the run ended (198/200):
``u0102``, whose way west-north-west leaned into the disc of ``u0124`` at rest on its goal, was found
stuck (``_stalled``) against the nearest unit ahead, ``u0105`` just beside it, which was coming nearer
its goal or had just been counted afresh: a queue that moves, so no deadlock; found stuck in turn 3 s
later, ``u0105`` (stopped by ``u0102``'s disc) took ``u0102``, just counted afresh, for a queue too,
and so on every 7 s.  Now a unit found stuck is stuck against the unit at rest whose disc cut it to
nothing (``deadlocks.Facing.stopping``): ``u0102`` goes round ``u0124``, and both arrive.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import _crowd
from pfp_service.world.separations import DispersionSettings

pytestmark = pytest.mark.unit

# u0124 at rest kept 60 m (a class of its own): u0102 stands on its disc at 63 m, u0105 on u0102's at
# 52.5 m, so the nearest unit ahead of u0102 is u0105, as in seed 2 (where both were 52.5 m off it)
ON = DispersionSettings(
    enabled=True,
    separation_m={"foot": 5.0, "wheeled": 50.0, "tracked": 60.0},
    classes={"u0000": "tracked"},
)


def _seed_2_at_887_s() -> _crowd.Crowd:
    """Seed 2's three units at 887 s, about ``u0102`` (here ``u0001``): ``u0124`` (``u0000``), at rest on its
    goal west of it, moved out to 63 m along its bearing; ``u0105`` (``u0002``) 10 m west of where it stood,
    south-south-west of ``u0102``, so it comes to its stop on ``u0102``'s disc 4 s in, still coming nearer
    its goal when ``u0102`` is first found stuck."""
    b0 = np.array((-796.8, 1877.8))
    a = np.array((-848.9, 1883.6)) - b0
    at_rest = tuple((a / np.hypot(*a) * 63.0).tolist())
    c = tuple((np.array((-823.3, 1832.5)) - b0 - (10.0, 0.0)).tolist())
    goal_b = tuple((np.array((-1155.0, 2020.0)) - b0).tolist())
    goal_c = tuple((np.array((-693.0, 2020.0)) - b0).tolist())
    return _crowd.Crowd(
        "a unit on the disc of one at rest, another on its own",
        starts=[at_rest, (0.0, 0.0), c],
        goals=[at_rest, goal_b, goal_c],
        kinds=["unmanned"] * 3,
        threats={},
        limit_s=200.0,
    )


def test_a_unit_stopped_by_one_at_rest_is_stuck_against_it_not_the_unit_beside_it_and_all_arrive():
    """On main with rules 1 and 2: no deadlock ever found, ``u0001`` and ``u0002`` stand the 200 s."""
    crowd = _seed_2_at_887_s()
    locks: list = []
    out = _crowd.simulate(crowd, ON, locks=locks)
    assert set(out.arrived_s) == set(crowd.ids()), f"arrived: {sorted(out.arrived_s)}"
    first = locks[0][1]
    assert (first.unit, first.other) == ("u0001", "u0000") and "goes round it" in first.reason
    assert locks[0][0] <= ON.deadlock_s
    assert out.not_cleared == 0 and out.longest_clearing_s <= 30.0
    assert out.closest_share >= 0.9
