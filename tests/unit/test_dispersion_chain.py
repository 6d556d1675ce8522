"""Deadlocks of three (issue 33, `h-deadlock7`): a unit stopped behind one that waits on a third is in a
queue, not in a deadlock with it; and a unit resolving a deadlock with a third is not handed another.

The gaps crowd's longest clearings on main (seeds 3, 5, 14: 31, 40 and 39 s) were each a unit found
stuck (``_stalled``) behind one that yielded to a third: ``u0194`` behind ``u0174``, which yielded to
``u0136`` (seed 5).  The unit behind was found deadlocked with the one it stood behind and backed off,
some 30 m from its goal, ground it then had to win back in slow traffic: the one ahead was not waiting
on it, and the back-off opened nothing.  Now it waits; the queue's head (the unit yielded to) is where
the deadlock is, found and resolved there.  With that rule, seed 20's longest (35 s) was a unit going
round one at rest whose round a third unit's deadlock undid (it was made to back off from that one,
by right of way): now that third unit resolves it.

Scripted: a unit that reports the same position every second (a vehicle that does not move as told)
stands where the rules need it.
"""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.wire import DeadlockEvent, Direction, DirectionStatus, Goal, UnitKind, UnitState
from pfp_service.world import events as ev
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.world import World, WorldSettings

pytestmark = pytest.mark.unit

_MOVES = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING, DirectionStatus.YIELDING)


def _run(
    seconds: int,
    starts: list[tuple[float, float]],
    goals: list[tuple[float, float]],
    kinds: list[UnitKind],
    stalled: int,
    late: dict[int, float] | None = None,
) -> tuple[list[tuple[float, DeadlockEvent]], list[tuple[float, Direction]], np.ndarray]:
    """Drive the units ``u0000``, ``u0001``, ... a second at a time, each along its direction (5 m at most,
    never past its reach), but unit ``stalled``, which stays where it starts; ``late``: units that report
    first at that time.  The deadlocks found, the directions, each unit's track (``(seconds, n, 2)``)."""
    late = late or {}
    world = World(
        WorldSettings(
            deliberation="deferred",
            unit_stale_s=1e9,
            unit_forget_s=None,
            dispersion=DispersionSettings(enabled=True),
        )
    )
    ids = [f"u{k:04d}" for k in range(len(starts))]
    pos = np.array(starts, dtype=float)
    found: list[tuple[float, DeadlockEvent]] = []
    said: list[tuple[float, Direction]] = []
    track = []
    done: list[ev.Input] = []
    for seq in range(1, seconds + 1):
        t = float(seq - 1)
        here = [k for k in range(len(ids)) if t >= late.get(k, 0.0)]
        inputs = [
            *done,
            *(ev.GoalSet(ids[k], Goal(position=goals[k])) for k in here if t == late.get(k, 0.0)),
        ]
        inputs += [
            ev.StateReported(
                ids[k], UnitState(position=(float(pos[k, 0]), float(pos[k, 1])), seq=seq, kind=kinds[k])
            )
            for k in here
        ]
        track.append(pos.copy())
        out = world.apply(inputs, t)
        done = [job.run() for job in out.jobs if not job.cancelled]
        found += [(t, e) for e in out.events if isinstance(e, DeadlockEvent)]
        said += [(t, d) for d in out.directions]
        for d in out.directions:
            k = ids.index(d.unit)
            if k != stalled and d.status in _MOVES:
                pos[k] += np.array(d.vector) * min(5.0, d.reach_m or 0.0)
    return found, said, np.array(track)


def test_a_unit_behind_one_yielding_to_a_third_waits_and_the_head_of_the_queue_resolves():
    """``u0001`` yields to manned ``u0000``, stalled in its way; ``u0002`` stands behind ``u0001``, its way north
    through it.  On main (``d47ca31``) ``u0002`` is found deadlocked with ``u0001`` at 6 s and backs off."""
    goals = [(-2000.0, 60.0), (0.0, 1000.0), (0.0, 1000.0)]
    kinds = [UnitKind.MANNED, UnitKind.UNMANNED, UnitKind.UNMANNED]
    found, said, track = _run(40, [(35.0, 60.0), (0.0, 0.0), (0.0, -55.0)], goals, kinds, stalled=0)
    reasons = [e.reason for _, e in found]
    assert any((e.unit, e.other) == ("u0001", "u0000") for _, e in found), reasons  # the head's deadlock
    assert not any(e.unit == "u0002" for _, e in found), reasons
    assert not any(d.unit == "u0002" and "backing off" in (d.reason or "") for _, d in said)
    to_goal = np.hypot(*(track[:, 2] - goals[2]).T)
    assert to_goal[-1] <= to_goal[0] - 50.0  # it goes on once the head has cleared


def test_a_unit_going_round_one_at_rest_keeps_its_round_when_a_third_stops_it():
    """``u0002``, its way north through ``u0000`` at rest on its goal, goes round it at 6 s, and is stopped by
    ``u0001`` (stalled, reporting from 3 s), each cut to nothing by the other.  On main (``d47ca31``), and with
    the queue rule alone, ``u0002`` (of lower priority) gives way: its round undone for a back-off."""
    starts = [(0.0, 0.0), (60.0, -70.0), (2.0, -56.0)]
    goals = [(0.0, 0.0), (-600.0, -70.0), (0.0, 600.0)]
    kinds = [UnitKind.UNMANNED] * 3
    found, said, _ = _run(30, starts, goals, kinds, stalled=1, late={1: 3.0})
    reasons = [e.reason for _, e in found]
    assert [(e.unit, e.other) for _, e in found[:2]] == [("u0002", "u0000"), ("u0001", "u0002")], reasons
    assert "each cut to nothing by the other" in found[1][1].reason
    after = [d for t, d in said if d.unit == "u0002" and found[1][0] <= t < found[1][0] + 6.0]
    assert after and all("going round u0000" in (d.reason or "") for d in after)
