"""Dispersion in the live world: separations by class, the push in the field, right of way and deadlocks.

Off unless ``DispersionSettings.enabled``: then the world is what it was,
bit for bit.  On, each ``apply`` that advises units does four things:

1. ``Dispersion.push``: a k-d tree over every unit the world holds a fresh
   position for (guided, arrived, without a goal: a friendly unit is in the
   way whatever it is doing), built once, and each advised unit's share of
   the repulsive term (``core.dispersion``), which it descends with the
   field (``core.batch.advise_many``: a unit on another route turns by it).
2. ``Dispersion.right_of_way``: a unit whose direction closes on a moving
   unit of higher priority within ``YIELD_AT`` separations holds, with
   status ``yielding`` and a reason naming the other unit, and goes when the
   other has drawn away (or makes room, when a unit is within about its
   separation).  Priority: manned before unmanned (unless ``manned_first``
   is off), then the smaller id.  The order is total, so no two units ever
   yield to each other.
3. A deadlock, a unit yielding for ``deadlock_s`` to a unit that has not
   drawn away, or a pushed unit no nearer its goal for ``deadlock_s`` (two
   units pushing each other to a standstill), is reported
   (``DeadlockEvent``) and broken: the unit of lower priority (or the one
   that can move) backs off, away and aside, for ``backoff_s``, then goes on
   as any unit does.  Detected within ``deadlock_s``, released ``backoff_s``
   later: a bounded time.
4. ``_short``: no direction takes a unit within ``KEEP`` separations of
   another; its reach is cut at that disc's edge.

A unit's separation is its mobility class's (``separations``); a pair keeps
the larger of its two.  Look-ahead points are the threat field's descent:
neighbours move meanwhile.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import msgspec
import numpy as np

from pfp_service.core.dispersion import PUSH, REACH, NeighbourIndex
from pfp_service.wire import DeadlockEvent, Direction, DirectionStatus, Event
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.units import UnitRecord, Verdict

__all__ = ["YIELD_AT", "Dispersion", "priority"]

YIELD_AT = 1.5  # a lower-priority unit closing on a higher one within this many separations holds
# a yielding unit pushed this hard (a neighbour within about its separation: PUSH (1 - 1 / REACH) is
# one at exactly the separation) moves away along its push instead of holding still
CROWDED = PUSH * (1.0 - 1.0 / REACH)
KEEP = 1.1  # no direction drives a unit within this many separations of another (``_short``)
_DRAWN_AWAY = 0.25  # a held-for unit that opens the gap by this share of the separation is passing
_MOVING = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)


def priority(rec: UnitRecord, manned_first: bool) -> tuple[int, str]:
    """The unit's right of way as a sort key: smaller goes first."""
    return (0 if manned_first and rec.kind == "manned" else 1, rec.id)


@dataclass(slots=True)
class _Hold:
    other: str
    since: float
    gap: float  # the distance to ``other`` when the hold began (or it last drew away)
    backoff_until: float = -math.inf


class Dispersion:
    """The world's dispersion: the neighbour index of this ``apply`` and the holds in force."""

    def __init__(
        self,
        settings: DispersionSettings,
        units: Mapping[str, UnitRecord],
        yielded: Callable[[UnitRecord, Verdict], None],
    ) -> None:
        self.settings = settings
        self._units = units  # the world's records, read (every unit with a fresh position is in the way)
        # what a held unit's record keeps is the units' owner's to write (``units.Units.yielded``)
        self._yielded = yielded
        self._held: dict[str, _Hold] = {}
        self._index: NeighbourIndex | None = None
        self._recs: list[UnitRecord] = []
        self._row: dict[str, int] = {}
        self._pushed: dict[str, list[float]] = {}  # each unit advised in this ``apply``: its push
        self._seps: dict[str, float] = {}  # each unit's separation, by its class: fixed by the settings
        self._stall: dict[
            str, tuple[float, float]
        ] = {}  # a pushed unit: its best distance to goal, and since

    def holding(self) -> int:
        """How many units hold (yield or back off) now."""
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
        recs = [r for r in self._units.values() if r.position is not None and not r.stale]
        self._recs, self._row = recs, {r.id: k for k, r in enumerate(recs)}
        seps = self._seps
        if len(seps) > 2 * len(self._units) + 64:  # forgotten units' go (bounded by the fleet)
            seps.clear()
        sep = self.settings.separation
        self._index = NeighbourIndex(
            np.array([r.position for r in recs], dtype=float).reshape(-1, 2),
            np.fromiter(
                (seps[u] if (u := r.id) in seps else seps.setdefault(u, sep(u)) for r in recs),
                dtype=float,
                count=len(recs),
            ),
        )
        push = PUSH * self._index.gradients(np.array([self._row[r.id] for r in guided], dtype=np.intp))
        self._pushed = dict(zip((r.id for r in guided), push.tolist()))
        return push

    def right_of_way(self, directions: list[Direction], first: int, now: float) -> list[Event]:
        """Hold (or back off) the units of ``directions[first:]`` that must yield, in place; the deadlocks found.

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
        blocker = self._blockers([directions[k] for k in moving])
        events: list[Event] = []
        for k, j in zip(moving, blocker):
            d = directions[k]
            i = self._row[d.unit]
            hold = self._held.get(d.unit)
            if hold is not None and hold.backoff_until > now and hold.other in self._row:
                directions[k] = self._back_off(d, i, self._row[hold.other], hold)
                continue
            if j < 0:
                self._held.pop(d.unit, None)
                lock = self._stalled(d, i, now)
                if lock is not None:
                    events.append(lock)
                    if (hold := self._held.get(d.unit)) is not None:  # this unit backs off, from now
                        directions[k] = self._back_off(d, i, self._row[hold.other], hold)
                continue
            other = self._recs[j].id
            gap = float(np.hypot(*(index.points[i] - index.points[j])))
            pair = float(max(index.seps[i], index.seps[j]))  # a Direction's reach_m: a float the wire encodes
            if hold is None or hold.other != other or hold.backoff_until > -math.inf:
                hold = self._held[d.unit] = _Hold(other, now, gap)
            elif gap > hold.gap + _DRAWN_AWAY * pair:  # it is passing: the clock starts again
                hold.since, hold.gap = now, gap
            elif now - hold.since >= s.deadlock_s:
                hold.backoff_until = now + s.backoff_s
                events.append(self._deadlock(d.unit, other, i, now - hold.since))
                directions[k] = self._back_off(d, i, j, hold)
                continue
            directions[k] = self._yield(d, i, j, gap, pair)
        self._short(directions, moving)
        return events

    def _short(self, directions: list[Direction], moving: list[int]) -> None:
        """Cut each moving direction's reach where it would enter a neighbour's ``KEEP`` separations, in place.

        A direction's ray against every neighbour's disc of ``KEEP`` times the
        pair's separation, in one vectorised pass: the unit goes no further
        than the disc's edge (0, holding, when it is inside one and closing),
        so no direction ever drives a unit into another's separation, whatever
        pushes it.  The margin is for the other unit, which moves meanwhile.
        """
        index = self._index
        assert index is not None
        go = [k for k in moving if directions[k].vector != (0.0, 0.0)]
        if not go:
            return
        rows = np.array([self._row[directions[k].unit] for k in go], dtype=np.intp)
        at = np.full(len(self._recs), -1, dtype=np.intp)
        at[rows] = np.arange(len(rows))
        vec = np.array([directions[k].vector for k in go], dtype=float).reshape(-1, 2)
        i, j = index.near(rows)
        n = at[i]
        rel = index.points[j] - index.points[i]
        along = (rel * vec[n]).sum(axis=1)
        keep_m = KEEP * np.maximum(index.seps[i], index.seps[j])
        across2 = (rel * rel).sum(axis=1) - along * along
        hit = (along > 0.0) & (across2 < keep_m * keep_m)
        enter = np.maximum(along[hit] - np.sqrt(np.maximum(keep_m[hit] ** 2 - across2[hit], 0.0)), 0.0)
        safe = np.full(len(go), np.inf)
        np.minimum.at(safe, n[hit], enter)
        for m in np.flatnonzero(np.isfinite(safe)).tolist():
            k, cut = go[m], float(safe[m])
            d = directions[k]
            if d.reach_m is None or cut < d.reach_m:
                directions[k] = msgspec.structs.replace(d, reach_m=cut)

    def _stalled(self, d: Direction, i: int, now: float) -> DeadlockEvent | None:
        """A deadlock without a hold: a pushed unit that has not come nearer its goal for ``deadlock_s``.

        Two units pushing each other to a standstill (head on, or one against
        a unit that stands still) are a deadlock too: the one of lower
        priority of the unit and its nearest neighbour backs off (the unit
        itself, if the neighbour is not moving).
        """
        index, s = self._index, self.settings
        assert index is not None
        px, py = self._pushed.get(d.unit, (0.0, 0.0))
        if (px == 0.0 and py == 0.0) or d.distance_to_goal is None:
            self._stall.pop(d.unit, None)
            return None
        best = self._stall.get(d.unit)
        if best is None or d.distance_to_goal < best[0] - _DRAWN_AWAY * index.seps[i]:
            self._stall[d.unit] = (d.distance_to_goal, now)
            return None
        if now - best[1] < s.deadlock_s:
            return None
        del self._stall[d.unit]
        _, jj = index.near(np.array([i]))
        if not len(jj):
            return None
        gaps = np.hypot(*(index.points[jj] - index.points[i]).T)
        j = int(jj[int(gaps.argmin())])
        me, other = self._recs[i], self._recs[j]
        first = s.manned_first
        can = other.last_status in _MOVING or other.last_status is DirectionStatus.YIELDING  # not at rest
        lower, higher = (other, me) if can and priority(other, first) > priority(me, first) else (me, other)
        self._held[lower.id] = _Hold(higher.id, best[1], float(gaps.min()), now + s.backoff_s)
        return self._deadlock(lower.id, higher.id, self._row[lower.id], now - best[1])

    def _blockers(self, moving: list[Direction]) -> list[int]:
        """For each direction, the row of the nearest unit it must yield to, or -1: one vectorised pass."""
        index, s = self._index, self.settings
        assert index is not None
        if not moving:
            return []
        rows = np.array([self._row[d.unit] for d in moving], dtype=np.intp)
        vec = np.array([d.vector for d in moving], dtype=float).reshape(-1, 2)
        at = np.full(len(self._recs), -1, dtype=np.intp)
        at[rows] = np.arange(len(rows))
        i, j = index.near(rows)
        rel = index.points[j] - index.points[i]
        gap = np.hypot(rel[:, 0], rel[:, 1])
        closing = (rel * vec[at[i]]).sum(axis=1) > 0.0
        close = closing & (gap < YIELD_AT * np.maximum(index.seps[i], index.seps[j]))
        i, j, gap = i[close], j[close], gap[close]
        # the order of right of way among the units of the pairs left (0 first): compared only within
        # them, it is the total order's, at the cost of the tick's reports, not of the fleet
        n = len(self._recs)
        used = np.unique(np.concatenate([i, j]))
        recs = [self._recs[u] for u in used.tolist()]
        first = np.fromiter((priority(r, s.manned_first)[0] for r in recs), dtype=np.intp, count=len(recs))
        rank = np.zeros(n, dtype=np.intp)
        rank[used[np.lexsort((np.array([r.id for r in recs]), first))]] = np.arange(len(recs))
        goes = np.zeros(n, dtype=bool)
        goes[used] = np.fromiter((self._goes(r) for r in recs), dtype=bool, count=len(recs))
        k = at[i]
        keep = (rank[j] < rank[i]) & goes[j]
        best = np.full(len(moving), -1, dtype=np.intp)
        near = np.full(len(moving), np.inf)
        for kk, jj, g in zip(k[keep].tolist(), j[keep].tolist(), gap[keep].tolist()):
            if g < near[kk]:
                near[kk], best[kk] = g, jj
        return best.tolist()

    def _goes(self, rec: UnitRecord) -> bool:
        """Whether a unit is moving under its own right of way (not holding, not still)."""
        return rec.last_vector is not None and rec.last_status in _MOVING and rec.id not in self._held

    def _yield(self, d: Direction, i: int, j: int, gap: float, pair: float) -> Direction:
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
        if crowded > CROWDED:  # a unit within about its separation: holding still is no place to wait
            vec = (-px / crowded, -py / crowded)
            reason = reason.replace("; goes when", "; making room, goes when")
            self._yielded(rec, Verdict(DirectionStatus.YIELDING, reason, rec.last_distance, vec))
            return _held(d, vec, pair, reason)
        self._yielded(rec, Verdict(DirectionStatus.YIELDING, reason, rec.last_distance, None))
        return _held(d, (0.0, 0.0), 0.0, reason)

    def _back_off(self, d: Direction, i: int, j: int, hold: _Hold) -> Direction:
        index = self._index
        assert index is not None
        ax, ay = (index.points[i] - index.points[j]).tolist()
        norm = math.hypot(ax, ay)
        ax, ay = (ax / norm, ay / norm) if norm > 0.0 else (-1.0, 0.0)
        px, py = self._pushed.get(d.unit, (0.0, 0.0))
        # away from the unit it yields to and aside (to its left as seen from it: head on, the two
        # no longer share a line), and from every other unit as the push says
        vx, vy = ax - ay - px, ay + ax - py
        v = math.hypot(vx, vy)
        vec = (vx / v, vy / v) if v > 0.0 else (0.0, 0.0)
        pair = float(max(index.seps[i], index.seps[j]))
        rec = self._recs[i]
        reason = (
            f"backing off from {hold.other} to clear a deadlock; goes on after {self.settings.backoff_s:g} s"
        )
        self._yielded(rec, Verdict(DirectionStatus.YIELDING, reason, rec.last_distance, vec))
        return _held(d, vec, pair, reason)

    def _deadlock(self, unit: str, other: str, i: int, held_s: float) -> DeadlockEvent:
        assert self._index is not None
        x, y = self._index.points[i].tolist()
        b = self.settings.backoff_s
        why = f"{unit} held {held_s:.0f} s for {other}, which did not draw away: {unit} backs off for {b:g} s"
        return DeadlockEvent(unit=unit, other=other, position=(x, y), held_s=held_s, backoff_s=b, reason=why)


def _held(d: Direction, vec: tuple[float, float], reach_m: float, reason: str) -> Direction:
    heading = None
    if vec != (0.0, 0.0):
        heading = math.degrees(math.atan2(vec[0], vec[1])) % 360.0
    return msgspec.structs.replace(
        d,
        status=DirectionStatus.YIELDING,
        vector=vec,
        heading_deg=heading,
        true_bearing_deg=None,
        lookahead=[],
        lookahead_geo=[],
        reach_m=reach_m,
        reason=reason,
    )
