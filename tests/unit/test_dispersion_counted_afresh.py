"""A unit counted afresh is no queue that moves until it comes nearer its goal (issue 33, gaps seed 2).

Two units crossing, each cut to nothing by the other, were each found stuck a few ticks after the
other; a unit found stuck is counted afresh (``Locks.forget``), and each then saw the other, just
counted afresh, as a queue that moves (``Locks.progressing``): neither deadlock was ever found, and
neither unit arrived (with the cut's moving neighbours and the pushed descent's turn across, from
885 s until the run ended).  A unit found stuck now judges the other strictly: counted afresh, it has
not come nearer until it does.  (Judged so everywhere, in the holds too, twice as many deadlocks
were found and backed off from, and the longest clearings grew.)
"""

from __future__ import annotations

import pytest

from pfp_service.world import deadlocks
from pfp_service.world.separations import DispersionSettings

pytestmark = pytest.mark.unit


def test_a_unit_counted_afresh_is_not_coming_nearer_its_goal_until_it_does():
    locks = deadlocks.Locks(DispersionSettings(enabled=True))
    locks.progressed("a", 100.0, 50.0, 0.0)
    assert locks.progressing("a", 1.0)  # first seen: counted from there, as before
    locks.forget("a")  # found stuck
    locks.progressed("a", 100.0, 50.0, 7.0)
    assert locks.stuck_for("a", 8.0) == 1.0  # its clock from now
    assert not locks.progressing("a", 8.0, strict=True), "counted afresh, not nearer: no queue that moves"
    assert locks.progressing("a", 8.0)  # for a hold, as before
    locks.progressed("a", 96.0, 50.0, 9.0)  # 4 m: under a tenth of the separation
    assert not locks.progressing("a", 10.0, strict=True)
    locks.progressed("a", 94.0, 50.0, 11.0)  # 6 m nearer: it comes nearer
    assert locks.progressing("a", 12.0, strict=True) and not locks.progressing("a", 17.0, strict=True)
