"""The mission's other planners as the world sees them: peers joining and leaving, twins, and the units that move.

Under ``--cluster`` a peer's token joining moves the units whose shards it
now owns (``ownership``), and one gone for the whole debounce (a timer on
the world's heap) gives them back; a unit handed over or taken over is the
units' owner's step (``units.Units``), and one taken over is guided from
its last mission at once.  A planner that answers this one's units too is a
conflict, decided here once: another id without ``--cluster`` (both answer
every unit), or this very id from another session under ``--cluster``
(units are shared by planner id: a twin cannot share, only collide).  Pure
values: ``now`` is a parameter.
"""

from __future__ import annotations

from collections.abc import Callable

from pfp_service.wire import ConflictEvent
from pfp_service.wire.messages import TerrainInfo
from pfp_service.world.events import Batch, PeerPlanner, PeerTerrain, WorldSettings
from pfp_service.world.ownership import Ownership
from pfp_service.world.timers import Timers
from pfp_service.world.units import UnitRecord, Units

__all__ = ["Cluster", "terrain_conflict"]


class Cluster:
    """Who guides which unit, as the mission's planners come and go.

    Args:
        start: the world's way to start a unit's mission (``World._start``).
        tell: the world's way to give a unit a fresh direction in this batch.
    """

    def __init__(
        self,
        settings: WorldSettings,
        book: Units,
        timers: Timers,
        start: Callable[[UnitRecord, Batch], None],
        tell: Callable[[UnitRecord, Batch], None],
    ) -> None:
        self.settings = settings
        self.own = Ownership(settings.planner_id, settings.cluster)
        self._book, self._timers, self._start, self._direct = book, timers, start, tell

    def peer(self, inp: PeerPlanner, b: Batch) -> None:
        """A planner's token came or went (``PeerPlanner``): units move, or a conflict is said."""
        s, planner = self.settings, inp.planner
        if inp.session is not None and s.cluster:  # this id from another session: never a peer
            if inp.alive:
                why = (
                    f"another planner (session {inp.session}) also serves mission {s.mission!r} as "
                    f"{s.planner_id!r}; --cluster shares units by planner id: give each its own --planner-id"
                )
                b.out.events.append(ConflictEvent(planner=s.planner_id, other=planner, reason=why))
        elif (
            not inp.alive
        ):  # acted on only if still gone after the debounce (a router restart flaps every token)
            if self.own.left(planner, b.now):
                self._timers.set(b.now + s.liveliness_debounce_s, "peer", planner)
        elif not self.own.joined(planner):
            return  # this planner, a known peer, or one back within the debounce: nothing moves
        elif s.cluster:
            self.rebalance(b)
        else:
            why = f"planner {planner!r} also serves mission {s.mission!r}; both answer every unit"
            b.out.events.append(ConflictEvent(planner=s.planner_id, other=planner, reason=why))

    def terrain(self, inp: PeerTerrain, b: Batch) -> None:
        """A peer plans over another DEM (another sha256, or none) than this one: it cannot share the units."""
        reason = terrain_conflict(inp.mine, inp.theirs, self.settings.mission, inp.planner)
        if reason is not None:
            b.out.events.append(
                ConflictEvent(planner=self.settings.planner_id, other=inp.planner, reason=reason)
            )

    def settle(self, planner: str, now: float, b: Batch) -> None:
        """A peer's ``peer`` timer is due at ``now``: gone for the whole debounce, its units move."""
        s = self.settings
        if self.own.settle(planner, now, s.liveliness_debounce_s) and s.cluster:
            self.rebalance(b)

    def rebalance(self, b: Batch) -> None:
        """The live planners changed: a unit taken over is guided from its last mission at once."""
        for rec in self._book.records.values():
            owned = self.own.owns(rec.id)
            if owned == rec.owned:
                continue
            if not owned:
                self._book.hand_over(rec)
                continue
            self._book.take_over(rec)
            if (
                rec.goal is not None and rec.position is not None and not rec.stale
            ):  # stale: at its next report
                self._start(rec, b)
            self._direct(rec, b)


def terrain_conflict(
    mine: TerrainInfo | None, theirs: TerrainInfo | None, mission: str, other: str
) -> str | None:
    """Why planner ``other`` cannot share ``mission`` with this one's terrain, or ``None`` if it can."""
    ours = mine.sha256 if mine is not None else None
    its = theirs.sha256 if theirs is not None else None
    if ours == its:
        return None

    def name(t: TerrainInfo | None) -> str:
        return f"{t.file} (sha256 {t.sha256[:12]})" if t is not None else "no terrain"

    return (
        f"planner {other!r} serves mission {mission!r} over {name(theirs)}, this one over {name(mine)}: "
        "their directions and previews disagree wherever the ground matters"
    )
