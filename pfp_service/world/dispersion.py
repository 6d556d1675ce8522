"""Dispersion in the live world: separations by class and team, the push in the field, right of way and deadlocks.

Off unless ``DispersionSettings.enabled``: then the world is what it was,
bit for bit.  On, each ``apply`` that advises units does four things:

1. ``Dispersion.push``: a k-d tree over every unit the world holds a fresh
   position for (guided, arrived, without a goal: a friendly unit is in the
   way whatever it is doing), built once while they stand (``neighbours``), and each advised unit's share of
   the repulsive term (``core.dispersion``), which it descends with the
   field (``core.batch.advise_many``: a unit on another route turns by it).
2. ``Dispersion.right_of_way``: a unit whose direction closes on a moving
   unit of higher priority within ``YIELD_AT`` separations (``right_of_way``)
   holds, with status ``yielding`` and a reason naming the other unit, and
   goes when the other has drawn away (or makes room, when a unit is within
   about its separation).
3. Deadlocks (``deadlocks``): a unit yielding for ``deadlock_s`` while the
   units it yields to neither draw away nor come nearer their own goals (a
   queue that moves is no deadlock), or a pushed unit no nearer its goal
   for ``deadlock_s``, is reported (``DeadlockEvent``) and resolved for a
   bounded time: against a unit at rest (arrived, trapped, without a goal)
   the blocked unit goes round it on its goal's side until it has passed
   it; between two units that can move, the one of lower priority backs
   off, away and aside, for ``backoff_s``, and when the same two lock again
   soon after, the other one does (escalation).  A unit whose resolution
   ends goes under its own right of way for ``deadlock_s`` (it yields to no
   one, ``_short`` still keeps it apart), so no unit yields for longer than
   ``deadlock_s`` plus its resolution with a deadlock in it; but a unit that
   backed off from one going round a third waits for that round first
   (``_waits``, bounded by the round).
4. ``_short``: no direction takes a unit within ``keep_apart.KEEP``
   separations of another (its separation alone from a unit giving way to
   it); its reach is cut at that disc's edge (``keep_apart``).  A back-off
   cut to nothing turns to a free way, and a unit holding still in the way
   of the unit it yields to makes room.  Two units each cut to nothing by
   the other for ``deadlock_s`` (one going round a unit at rest: at once)
   are one deadlock (``_facing_lock``).

A unit's separation is its mobility class's (``separations``), or its
team's ``separation_m`` towards the members of its team; a pair keeps the
larger of its two, and relaxes near a shared goal
(``core.dispersion.pair_separation``).  Look-ahead points are the threat
field's descent: neighbours move meanwhile.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

from pfp_service.core.dispersion import PUSH, REACH, NeighbourIndex
from pfp_service.wire import DeadlockEvent, Direction, DirectionStatus, Event
from pfp_service.world import deadlocks, keep_apart
from pfp_service.world.deadlocks import Hold
from pfp_service.world.neighbours import TEAM_WIDEST, FleetIndex, TeamOf
from pfp_service.world.right_of_way import YIELD_AT, blockers, priority
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.units import UnitRecord, Verdict

__all__ = ["STRAIGHT_AT", "TEAM_WIDEST", "YIELD_AT", "Dispersion", "TeamOf", "priority"]

# a yielding unit pushed this hard (a neighbour within about its separation: PUSH (1 - 1 / REACH) is
# one at exactly the separation) moves away along its push instead of holding still
CROWDED = PUSH * (1.0 - 1.0 / REACH)
# a unit whose way to its goal points this straight at another (within a degree) comes at it head on: its
# push on the other is along their line, with nothing to turn either aside (off the line by half a metre
# in 60 m, the push turns them, and they pass)
STRAIGHT_AT = math.cos(math.radians(1.0))
_DRAWN_AWAY = 0.25  # a held-for unit that opens the gap by this share of the separation is passing
_MOVING = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)
_GOING = (*_MOVING, DirectionStatus.YIELDING)  # a unit in none of these is at rest (``_lock``)


class Dispersion:
    """The world's dispersion: the neighbour index of this ``apply`` and the holds in force."""

    def __init__(
        self,
        settings: DispersionSettings,
        units: Mapping[str, UnitRecord],
        yielded: Callable[[UnitRecord, Verdict], None],
        team_of: TeamOf | None = None,
        version: Callable[[], object] | None = None,
    ) -> None:
        self.settings = settings
        self._units = units  # the world's records, read (every unit with a fresh position is in the way)
        # what a held unit's record keeps is the units' owner's to write (``units.Units.yielded``)
        self._yielded = yielded
        # the fleet's index, kept while ``version`` (where the units are, the teams) stands: a wave's shares
        self._fleet = FleetIndex(settings, units, team_of, version)
        self._held: dict[str, Hold] = {}
        self._locks = deadlocks.Locks(settings)
        self._facing = deadlocks.Facing()
        self._index: NeighbourIndex | None = None
        self._recs: list[UnitRecord] = []
        self._row: dict[str, int] = {}
        self._pushed: dict[str, list[float]] = {}  # each unit advised in this ``apply``: its push
        self._resolving: dict[tuple[int, int], float] = {}  # this tick's resolutions' pair separations

    def holding(self) -> int:
        """How many units hold (yield, back off or go round) now."""
        return len(self._held)

    def push(self, guided: list[UnitRecord]) -> np.ndarray | None:
        """Each of ``guided``'s dispersion gradient (``PUSH * grad phi``), ``(len(guided), 2)``; ``None`` when off.

        If the index cannot be built (a position the tree refuses), this
        ``apply`` goes without dispersion: the field alone, as when off.
        """
        self._index = None
        if not self.settings.enabled or not guided:
            return None
        try:
            return self._push(guided)
        except Exception:
            self._index = None
            return None

    def _push(self, guided: list[UnitRecord]) -> np.ndarray:
        self._index, self._recs, self._row = self._fleet()
        push = PUSH * self._index.gradients(np.array([self._row[r.id] for r in guided], dtype=np.intp))
        self._pushed = dict(zip((r.id for r in guided), push.tolist()))
        return push

    def right_of_way(self, directions: list[Direction], first: int, now: float) -> list[Event]:
        """Hold (or resolve a deadlock for) the units of ``directions[first:]`` that must yield, in place; the deadlocks found.

        Only units advised in this ``apply`` (after ``push``) are judged; the
        others keep their holds until they are advised again.
        """
        index, s = self._index, self.settings
        if index is None:
            return []
        moving = [
            k
            for k in range(first, len(directions))
            if (d := directions[k]).status in _MOVING and d.unit in self._row
        ]
        locks = self._locks
        if len(self._held) + len(locks) > 2 * len(self._row) + 64:  # units forgotten meanwhile: theirs go
            self._held = {u: h for u, h in self._held.items() if u in self._row}
            locks.keep(self._row)
        for k in moving:  # who is coming nearer its goal, before anyone is judged by it
            d = directions[k]
            locks.progressed(d.unit, d.distance_to_goal, float(index.seps[self._row[d.unit]]), now)
        rows = np.array([self._row[directions[k].unit] for k in moving], dtype=np.intp)
        found, gaps = blockers(
            index, self._recs, self._held, s.manned_first, [directions[k] for k in moving], rows
        )
        # each blocked unit's pair separation, all in one pass (elementwise: as one pair's alone)
        pairs = np.zeros(len(moving))
        blocked = found >= 0
        pairs[blocked] = index.pair_seps(rows[blocked], found[blocked])
        self._resolving = self._resolution_seps(directions, moving, rows)
        events: list[Event] = []
        for k, i, j, gap, pair in zip(moving, rows.tolist(), found.tolist(), gaps.tolist(), pairs.tolist()):
            d = directions[k]
            hold = self._held.get(d.unit)
            if hold is not None and (
                hold.until > -math.inf or hold.waits
            ):  # a resolution, or a wait after one
                if hold.until > now and hold.other in self._row and not self._passed(hold, i):
                    directions[k] = self._resolve(d, i, self._row[hold.other], hold)
                    continue
                del self._held[d.unit]
                if (waits := self._waits(d, i, hold, now)) is not None:
                    directions[k] = waits
                    continue
                locks.resolved(d.unit, now)
                hold = None
            if locks.in_grace(d.unit, now):
                j = -1
            if j < 0:
                self._held.pop(d.unit, None)
                if (lock := self._stalled(d, i, now)) is not None:
                    events.append(lock)
                    if (hold := self._held.get(d.unit)) is not None:  # this unit resolves it, from now
                        directions[k] = self._resolve(d, i, self._row[hold.other], hold)
                continue
            other = self._recs[j].id
            if hold is None:
                hold = self._held[d.unit] = Hold(other, now, gap, began=now)
            elif now - hold.began >= deadlocks.STARVED * s.deadlock_s:  # a stream that never ends: its turn
                del self._held[d.unit]
                locks.resolved(d.unit, now)
                continue
            elif hold.other != other:  # yielding still, to another: the clock runs on
                hold.other, hold.gap = other, gap
            elif (
                now - hold.since >= s.deadlock_s
                and gap <= hold.gap + _DRAWN_AWAY * pair
                and not self._queue(i, j, now)
            ):  # held for a unit neither passing nor coming nearer its goal (past this one)
                if (lock := self._lock(i, j, now - hold.since, now)) is not None:
                    events.append(lock)
                if (mine := self._held.get(d.unit)) is not None and mine.until > now:
                    directions[k] = self._resolve(d, i, j, mine)
                    continue
            elif gap > hold.gap + _DRAWN_AWAY * pair or self._queue(i, j, now):
                hold.since, hold.gap = now, gap  # it is passing, or a queue that moves: no deadlock yet
            directions[k] = self._yield(d, i, j, gap, pair)
        return events + self._short(directions, moving, now)

    def _short(self, directions: list[Direction], moving: list[int], now: float) -> list[Event]:
        """Cut each moving direction's reach where it would enter a neighbour's ``KEEP`` separations
        (``keep_apart``); two that stop each other are one deadlock (``_facing_lock``)."""
        index = self._index
        assert index is not None
        go = [k for k in moving if directions[k].vector != (0.0, 0.0)]
        if not go:
            self._facing.pairs([], now)  # no unit stopped in this apply
            return []
        rows = np.array([self._row[directions[k].unit] for k in go], dtype=np.intp)
        gives_way = keep_apart.giving_way(index, self._row, self._held, directions, moving)
        stopped = keep_apart.cut(index, rows, directions, go, gives_way)
        stopped = keep_apart.free_ways(index, self._row, self._held, directions, stopped, now)
        for m in keep_apart.make_room(index, self._row, directions, moving, stopped, gives_way):
            rec, d = self._recs[self._row[directions[m].unit]], directions[m]
            self._yielded(rec, Verdict(DirectionStatus.YIELDING, d.reason, rec.last_distance, d.vector))
        at = {directions[k].unit: k for k, _ in stopped}
        events: list[Event] = []
        for a, b, held_s in self._facing.pairs(
            [(directions[k].unit, self._recs[j].id) for k, j in stopped], now
        ):
            if (lock := self._facing_lock(a, b, held_s, now)) is not None:
                events.append(lock)
                k = at[lock.unit]
                i, j = self._row[lock.unit], self._row[lock.other]
                directions[k] = self._resolve(directions[k], i, j, self._held[lock.unit])
                keep_apart.cut(index, np.array([i], dtype=np.intp), directions, [k], gives_way)
        return events

    def _facing_lock(self, a: str, b: str, held_s: float, now: float) -> DeadlockEvent | None:
        """Units ``a`` and ``b``, each cut to nothing by the other for ``held_s``: for ``deadlock_s``,
        whatever they are doing, one deadlock (``deadlocks.Facing``), found once; when either is going
        round a unit at rest, at once (two rounds: their two resolutions are one).  A round cut to nothing
        is a resolution failing: waiting ``deadlock_s`` on it spent a quarter of the round (the gaps
        crowd's seed 2, issue 33).  The one that gave way waits after its back-off while the other's
        round lasts (``_waits``).

        The one that backs off (right of way, ``Locks.who_backs_off``; not one
        resolving a deadlock with a third, ``_busy``, when the other is free)
        gives way, backing off from the other for ``backoff_s``; the other passes.
        Found stuck (``_stalled``) a few ticks apart, each is counted
        afresh and the other sees it as a queue that moves: the cut sees
        the standstill as it is.
        """
        s, index = self.settings, self._index
        assert index is not None
        live = [h for u in (a, b) if (h := self._held.get(u)) is not None and h.until > now]
        if any(h.other in (a, b) for h in live):  # this one's, in resolution already
            return None
        going = [u for u in (a, b) if (h := self._held.get(u)) is not None and h.until > now and h.round]
        if not going and held_s < s.deadlock_s:  # a round stopped is a resolution failing: found at once
            return None
        first = s.manned_first
        ra, rb = self._units[a], self._units[b]
        lower, higher = (a, b) if priority(ra, first) > priority(rb, first) else (b, a)
        giver, passer = (lower, higher) if self._locks.who_backs_off(lower, higher, now) else (higher, lower)
        if self._busy(giver, now) and not self._busy(passer, now):  # resolving with a third: not undone
            giver, passer = passer, giver
            self._locks.backed_off(giver, passer, now)
        g, p = self._row[giver], self._row[passer]
        gap = float(np.hypot(*(index.points[g] - index.points[p])))
        self._held[giver] = Hold(passer, now, gap, until=now + s.backoff_s)
        return deadlocks.event(
            giver,
            passer,
            index.points[g],
            held_s,
            s.backoff_s,
            False,
            None,
            facing=True,
            rounds=len(going) == 2,
            rounding=going[0] if len(going) == 1 else None,
        )

    def _stalled(self, d: Direction, i: int, now: float) -> DeadlockEvent | None:
        """A deadlock without a hold: a pushed unit that has not come nearer its goal for ``deadlock_s``.

        Two units pushing each other to a standstill (head on, or one against
        a unit at rest) are a deadlock too, with the nearest unit at rest
        whose disc cut it to nothing in the last ``apply``
        (``Facing.stopping``), else the nearest unit ahead (on the goal's
        side; else the nearest): ``_lock`` says who resolves it.  A unit at
        rest never draws away, so waiting is no way past it; the nearest
        ahead may only stand beside it: stopped by a unit at rest, a unit
        took one just beside it, itself found stuck and so counted afresh,
        for a queue that moves, and stood for good.
        """
        index = self._index
        assert index is not None
        px, py = self._pushed.get(d.unit, (0.0, 0.0))
        if px == 0.0 and py == 0.0:
            return None
        stuck = self._locks.stuck_for(d.unit, now)
        if stuck < self.settings.deadlock_s:
            return None
        stops = [
            self._row[u]
            for u in self._facing.stopping(d.unit)
            if u in self._row and self._recs[self._row[u]].last_status not in _GOING
        ]
        jj = np.array(stops, dtype=np.intp) if stops else index.near(np.array([i]))[1]
        if not len(jj):
            return None
        rel = index.points[jj] - index.points[i]
        gaps = np.hypot(rel[:, 0], rel[:, 1])
        ahead = (rel @ np.array(self._towards(i, d.vector))) > 0.0
        j = int(jj[int(np.where(ahead, gaps, gaps + 1e9).argmin())])
        self._locks.forget(d.unit)
        if self._queue(i, j, now):  # behind a unit that comes nearer its goal: a queue
            return None
        return self._lock(i, j, stuck, now)

    def _queue(self, i: int, j: int, now: float) -> bool:
        """Whether the unit at row ``i``, held or stopped by the one at ``j``, is in a queue that moves.

        It is when ``j`` comes nearer its goal, unless that goal lies straight
        through ``i`` (``STRAIGHT_AT``): head on, on one line, the push has no
        side to it, and ``j``'s progress is ``i`` pushed back before it for
        as long as ``j`` goes.  It is, too, when ``j`` waits on a third unit
        (yields to it, or backs off from it): the queue's head (``deadlocks``).
        """
        theirs = self._held.get(self._recs[j].id)
        if (
            theirs is not None
            and not theirs.round
            and theirs.other != self._recs[i].id
            and theirs.other in self._row
        ):
            return True  # ``j`` waits on a third (or backs off from it): a queue, whose head resolves
        if not self._locks.progressing(self._recs[j].id, now):
            return False
        index = self._index
        assert index is not None
        rx, ry = (index.points[i] - index.points[j]).tolist()
        r = math.hypot(rx, ry)
        tx, ty = self._towards(j, (0.0, 0.0))
        return r == 0.0 or (rx * tx + ry * ty) <= STRAIGHT_AT * r

    def _lock(self, i: int, j: int, held_s: float, now: float) -> DeadlockEvent | None:
        """A deadlock between the units at rows ``i`` (found blocked) and ``j``: who resolves it, how, and its event.

        ``None`` when ``j`` already resolves a deadlock with ``i``: the same
        one, found from its other side (two units head on are each blocked by
        the other in one tick). A second resolution would be escalation's,
        and both would back off, meet again and lock again.  The unit right of
        way would send resolves it, unless it resolves one with a third
        (``_busy``): then the one found blocked does (``deadlocks``).
        """
        index, s = self._index, self.settings
        assert index is not None
        me, other = self._recs[i], self._recs[j]
        theirs = self._held.get(other.id)
        if theirs is not None and theirs.until > now and theirs.other == me.id:
            if (mine := self._held.get(me.id)) is not None:
                mine.since = mine.began = now  # the other makes way: this one holds on, its clocks from now
            return None
        at_rest = not (other.last_status in _MOVING or other.last_status is DirectionStatus.YIELDING)
        if at_rest:  # it will not move: go round it
            mover, blocker, round_ = me, other, True
        else:
            first = s.manned_first
            lower, higher = (other, me) if priority(other, first) > priority(me, first) else (me, other)
            mover, blocker = (
                (lower, higher) if self._locks.who_backs_off(lower.id, higher.id, now) else (higher, lower)
            )
            if mover is other and self._busy(other.id, now):  # resolving one with a third: not undone
                mover, blocker = me, other
                self._locks.backed_off(me.id, other.id, now)
            round_ = False
        until = now + (deadlocks.ROUND_BACKOFFS * s.backoff_s if round_ else s.backoff_s)
        m, b = self._row[mover.id], self._row[blocker.id]
        gap = float(np.hypot(*(index.points[m] - index.points[b])))
        self._held[mover.id] = Hold(blocker.id, now, gap, until=until, round=round_)
        if mover is not me and (mine := self._held.get(me.id)) is not None:
            mine.since = mine.began = now  # the other makes way: this one holds on, its clocks from now
        return deadlocks.event(
            mover.id, blocker.id, index.points[m], held_s, until - now, round_, other.last_status
        )

    def _waits(self, d: Direction, i: int, hold: Hold, now: float) -> Direction | None:
        """A unit whose back-off ended (or that waits after one), while the unit it gave way to resolves a
        deadlock with a third and has not drawn away: it yields to that one, its grace from when it stops.

        Under its grace at once, it drove straight back into the round it had
        made way for, was stopped by it and backed off again (``deadlocks``).
        """
        other = self._held.get(hold.other)
        if hold.round or other is None or other.other == d.unit or not self._busy(hold.other, now):
            return None
        index = self._index
        assert index is not None
        j = self._row[hold.other]
        gap = float(np.hypot(*(index.points[i] - index.points[j])))
        pair = float(index.pair_seps(np.array([i]), np.array([j]))[0])
        start = gap if not hold.waits else hold.gap
        # the other's way: its round's (backing off, its push's: not known before it is advised)
        wx, wy = 0.0, 0.0
        if other.round:
            rest = self._row[other.other]
            sep = float(index.pair_seps(np.array([j]), np.array([rest]))[0])
            wx, wy = deadlocks.round_vector(
                index.points[j] - index.points[rest], self._towards(j, (0.0, 0.0)), sep
            )
        rx, ry = (index.points[i] - index.points[j]).tolist()
        if gap > start + _DRAWN_AWAY * pair or wx * rx + wy * ry <= 0.0:  # drawn away, or its way past
            return None
        self._held[d.unit] = Hold(hold.other, hold.since, start, began=hold.began, waits=True)
        return self._yield(d, i, j, gap, pair, room=False)

    def _busy(self, unit: str, now: float) -> bool:
        """Whether ``unit`` resolves a deadlock (backing off, going round) in force now."""
        hold = self._held.get(unit)
        return hold is not None and hold.until > now and hold.other in self._row

    def _towards(self, i: int, otherwise: tuple[float, float]) -> tuple[float, float]:
        """The unit's way to its goal, as a unit vector (``otherwise`` when it has no goal, or is on it)."""
        rec, index = self._recs[i], self._index
        assert index is not None
        if rec.goal is not None:
            gx, gy = (np.asarray(rec.goal.position, dtype=float) - index.points[i]).tolist()
            norm = math.hypot(gx, gy)
            if norm > 0.0:
                return gx / norm, gy / norm
        return otherwise

    def _passed(self, hold: Hold, i: int) -> bool:
        """Whether a unit going round another has it behind (on the far side from its goal)."""
        if not hold.round:
            return False
        index = self._index
        assert index is not None
        j = self._row[hold.other]
        tx, ty = self._towards(i, (0.0, 0.0))
        rx, ry = (index.points[j] - index.points[i]).tolist()
        return bool(rx * tx + ry * ty <= 0.0)

    def _yield(self, d: Direction, i: int, j: int, gap: float, pair: float, room: bool = True) -> Direction:
        rec, other = self._recs[i], self._recs[j]
        why = "manned first" if other.kind == "manned" and rec.kind != "manned" else "by id"
        if why == "manned first" and not self.settings.manned_first:
            why = "by id"
        reason = (
            f"yielding to {other.id} (right of way {why}): {gap:.0f} m away, separation {pair:.0f} m;"
            " goes when it has passed"
        )
        px, py = self._pushed.get(rec.id, (0.0, 0.0))
        crowded = math.hypot(px, py)
        if (
            room and crowded > CROWDED
        ):  # a unit within about its separation: holding still is no place to wait
            vec = (-px / crowded, -py / crowded)
            reason = reason.replace("; goes when", "; making room, goes when")
            self._yielded(rec, Verdict(DirectionStatus.YIELDING, reason, rec.last_distance, vec))
            return deadlocks.held(d, vec, pair, reason)
        self._yielded(rec, Verdict(DirectionStatus.YIELDING, reason, rec.last_distance, None))
        return deadlocks.held(d, (0.0, 0.0), 0.0, reason)

    def _resolution_seps(
        self, directions: list[Direction], moving: list[int], rows: np.ndarray
    ) -> dict[tuple[int, int], float]:
        """The pair separation of each resolution in force among ``moving``, all in one pass (elementwise:
        as one pair's alone), for ``_resolve``; a resolution begun in this tick asks for its own."""
        index = self._index
        assert index is not None
        pairs = [
            (i, self._row[h.other])
            for k, i in zip(moving, rows.tolist())
            if (h := self._held.get(directions[k].unit)) is not None
            and h.until > -math.inf
            and h.other in self._row
        ]
        if not pairs:
            return {}
        ii, jj = np.array(pairs, dtype=np.intp).T
        return dict(zip(pairs, index.pair_seps(ii, jj).tolist()))

    def _resolve(self, d: Direction, i: int, j: int, hold: Hold) -> Direction:
        """The direction of a unit resolving a deadlock: round the unit at rest, or backing off from it."""
        index = self._index
        assert index is not None
        pair = self._resolving.get((i, j))
        if pair is None:
            pair = float(index.pair_seps(np.array([i]), np.array([j]))[0])
        rel = index.points[i] - index.points[j]
        if hold.round:
            vec = deadlocks.round_vector(rel, self._towards(i, d.vector), pair)
        else:
            vec = deadlocks.back_off_vector(rel, self._pushed.get(d.unit, (0.0, 0.0)))
        rec = self._recs[i]
        reason = deadlocks.resolving(hold, self._recs[j].last_status)
        self._yielded(rec, Verdict(DirectionStatus.YIELDING, reason, rec.last_distance, vec))
        return deadlocks.held(d, vec, pair, reason)
