"""Dispersion's deadlocks: who is coming nearer its goal, who resolves a deadlock and how, for how long.

A deadlock (``dispersion``) is resolved for a bounded time by one unit of
the two: against a unit at rest it goes round it (``round_vector``, at most
``ROUND_BACKOFFS`` back-offs long, ending once the unit at rest is behind
it); between two units that can move, the lower-priority one backs off
(``back_off_vector``) for ``backoff_s``, and if the same two lock again
within ``ESCALATE`` times ``deadlock_s + backoff_s``, the one that did not
back off last time does (``Locks.who_backs_off``): a pair never repeats one
failed resolution.  A unit whose resolution ended has ``deadlock_s`` of
grace (``Locks.in_grace``): it yields to no one meanwhile, so it gets a
chance to go, and no stretch of yielding with a deadlock in it outlasts
``deadlock_s`` plus one resolution.

Two units each cut to nothing by the other's disc (``keep_apart.cut``,
``Facing``) hold each other, whatever they are doing: for ``deadlock_s``,
they are one deadlock, found at once, resolved by right of way: the one
that backs off (``Locks.who_backs_off``) gives way for ``backoff_s``, the
other passes.  Two going round units at rest are one at the first tick:
towards each other in the one lane between the units at rest, they stopped
each other for as long as their rounds lasted, then found their units at
rest again and went round them again, for ever.  A unit found stuck
(``dispersion``'s ``_stalled``) is stuck against the unit at rest whose
disc stopped it (``Facing.stopping``), when one did, not the nearest unit
ahead, which may merely stand beside it.

Deadlocks of three (issue 33, ``h-deadlock7``): a unit stopped behind one
that waits on a third (yields to it, or backs off from it) is in a queue,
not in a deadlock with the one ahead: the deadlock, if any, is at the
queue's head, found and resolved there within ``deadlock_s`` plus one
resolution (or ``STARVED``), and the queue then moves.  Found deadlocked
with the one ahead, the unit behind backed off some 30 m from its goal,
opened nothing (the one ahead was not waiting on it), and won the ground
back in slow traffic: the gaps crowd's longest clearings (31-41 s).  A unit
going round one at rest is no such head: its round may stand as long as
``ROUND_BACKOFFS``.  And a unit resolving a deadlock with a third (going
round, backing off) is not handed a second resolution by right of way, which
undid the first (a round given up for a back-off, then begun again): the
other unit of the new deadlock resolves it (``Locks.backed_off``), unless it
resolves one too.

A round stopped (issue 33, ``h-deadlock8``): a unit going round one at rest
and a unit it stops, each cut to nothing by the other, are one deadlock at
once (a round is a resolution already, bounded, and waiting ``deadlock_s``
spent a quarter of it); and the unit that gave way to it, its back-off
over, waits for the round (``Hold.waits``: it yields to the unit going
round, holding still) until that one's way is past it, it has drawn away,
or its round ends, and only then has its grace: at once under its grace, it
drove back into the round and backed off again (the gaps crowd's seed 2,
42 s).

Progress (``Locks.progressed``) is what tells a queue from a deadlock: a
unit whose distance to its goal fell by ``PROGRESS`` of its separation
within ``deadlock_s`` is coming nearer it, and a unit yielding to it (or
pushed to a standstill behind it) is in a queue that moves, not in a
deadlock; but a unit that has yielded ``STARVED`` times ``deadlock_s`` in
all, whomever to, takes its turn (the grace, without backing off): a stream
of units that never ends does not hold it for ever.
"""

from __future__ import annotations

import math
from collections.abc import Container
from dataclasses import dataclass

import msgspec
import numpy as np

from pfp_service.wire import DeadlockEvent, Direction, DirectionStatus
from pfp_service.world.separations import DispersionSettings

__all__ = [
    "ASIDE",
    "ESCALATE",
    "PROGRESS",
    "ROUND_AT",
    "ROUND_BACKOFFS",
    "STARVED",
    "Facing",
    "Hold",
    "Locks",
    "aside_vector",
    "back_off_vector",
    "event",
    "held",
    "meet",
    "resolving",
    "round_vector",
]

PROGRESS = 0.1  # a unit whose distance to goal falls by this share of its separation comes nearer it
ESCALATE = 3.0  # two units locking again within this many (deadlock_s + backoff_s): the other backs off
STARVED = 2.0  # a unit yielding this many ``deadlock_s`` in all, to units that move, takes its turn
ROUND_BACKOFFS = 4.0  # going round a unit at rest lasts at most this many ``backoff_s``
ROUND_AT = 1.2  # ... at this many separations from it: outside ``KEEP``, so the cut does not stop it
ASIDE = 2.0  # a back-off goes this many times as far aside as away from the other unit (63 degrees off)


@dataclass(slots=True)
class Hold:
    """A unit's hold: the unit it yields to (or resolves a deadlock with), since when, and the resolution."""

    other: str
    since: float
    gap: float  # the distance to ``other`` when the hold began (or it last drew away)
    until: float = -math.inf  # a deadlock's resolution in force until then
    began: float = -math.inf  # when the unit began to yield (to whomever), for ``STARVED``
    round: bool = False  # the resolution goes round ``other`` (at rest), rather than backing off
    waits: bool = False  # it backed off from ``other`` and waits while ``other`` resolves its own deadlock


class Locks:
    """Each unit's progress towards its goal, its grace after a resolution, and each pair's last deadlock."""

    def __init__(self, settings: DispersionSettings) -> None:
        self.settings = settings
        self._best: dict[str, tuple[float, float]] = {}  # unit -> (its best distance to goal, since when)
        self._grace: dict[str, float] = {}  # unit -> until when it yields to no one
        self._pairs: dict[tuple[str, str], tuple[float, str]] = {}  # pair -> (when it locked, who backed off)

    def __len__(self) -> int:
        """How many units it keeps something for."""
        return len(self._best) + len(self._grace)

    def progressed(self, unit: str, distance: float | None, sep_m: float, now: float) -> None:
        """Note the unit's distance to its goal (``None``: no goal) in this ``apply``."""
        if distance is None:
            self._best.pop(unit, None)
            return
        best = self._best.get(unit)
        if best is None or distance < best[0] - PROGRESS * sep_m:
            self._best[unit] = (distance, now)

    def progressing(self, unit: str, now: float) -> bool:
        """Whether the unit came nearer its goal within the last ``deadlock_s``."""
        best = self._best.get(unit)
        return best is not None and now - best[1] < self.settings.deadlock_s

    def stuck_for(self, unit: str, now: float) -> float:
        """How long the unit has come no nearer its goal, in seconds (0 when unknown)."""
        best = self._best.get(unit)
        return 0.0 if best is None else now - best[1]

    def forget(self, unit: str) -> None:
        """Count the unit's progress afresh from its next distance (a deadlock found, or resolved)."""
        self._best.pop(unit, None)

    def resolved(self, unit: str, now: float) -> None:
        """The unit's resolution ended: grace for ``deadlock_s``, and its progress counted afresh."""
        self._grace[unit] = now + self.settings.deadlock_s
        self.forget(unit)

    def in_grace(self, unit: str, now: float) -> bool:
        """Whether the unit goes under its own right of way (after a resolution)."""
        until = self._grace.get(unit)
        if until is None:
            return False
        if until <= now:
            del self._grace[unit]
            return False
        return True

    def who_backs_off(self, lower: str, higher: str, now: float) -> bool:
        """Whether the lower-priority unit of a deadlocked pair backs off (``False``: the higher one does)."""
        s = self.settings
        window = ESCALATE * (s.deadlock_s + s.backoff_s)
        key = (lower, higher) if lower < higher else (higher, lower)
        last = self._pairs.get(key)
        lower_goes = last is None or now - last[0] >= window or last[1] != lower
        self._pairs[key] = (now, lower if lower_goes else higher)
        if len(self._pairs) > 4096:  # bounded: only the pairs that locked within the window matter
            self._pairs = {k: v for k, v in self._pairs.items() if now - v[0] < window}
        return lower_goes

    def backed_off(self, mover: str, other: str, now: float) -> None:
        """Note that ``mover`` backs off from ``other`` now, whoever right of way would have sent."""
        key = (mover, other) if mover < other else (other, mover)
        self._pairs[key] = (now, mover)

    def keep(self, units: Container[str]) -> None:
        """Forget every unit not in ``units`` (the world forgot them): the memory stays bounded."""
        self._best = {u: b for u, b in self._best.items() if u in units}
        self._grace = {u: g for u, g in self._grace.items() if u in units}


class Facing:
    """Pairs of units each cut to nothing by the other, and since when (``keep_apart.cut``'s stopped pairs);
    and who stopped each unit in the last ``apply``."""

    def __init__(self) -> None:
        self._since: dict[tuple[str, str], float] = {}  # (a, b), a < b -> since when each stops the other
        self._by: dict[str, list[str]] = {}  # unit -> the units whose discs stopped it, in the last apply

    def stopping(self, unit: str) -> list[str]:
        """The units whose discs cut ``unit`` to nothing in the last ``apply`` (none: it was not stopped)."""
        return self._by.get(unit, [])

    def pairs(self, stopped: list[tuple[str, str]], now: float) -> list[tuple[str, str, float]]:
        """Each pair in ``stopped`` (unit, the unit whose disc stops it) both ways, with how long it has held.

        Only the pairs seen in this ``apply`` are kept: a pair that parts and
        meets again starts afresh, and the memory is this tick's pairs.
        """
        cut = set(stopped)
        self._by = {}
        for a, b in stopped:
            self._by.setdefault(a, []).append(b)
        since = {}
        for a, b in sorted(cut):
            if a < b and (b, a) in cut:
                since[(a, b)] = self._since.get((a, b), now)
        self._since = since
        return [(a, b, now - t) for (a, b), t in since.items()]


def round_vector(away: np.ndarray, towards: tuple[float, float], pair_m: float) -> tuple[float, float]:
    """Round a unit at rest on the side of the goal: the shortest way, grazing its disc of ``ROUND_AT`` separations.

    Outside the disc, along the line from the unit that just touches it (a
    tangent); on it, along it, drawn back onto it when off.

    Args:
        away: from the unit at rest to the one going round it, in metres.
        towards: the way to the goal of the one going round, a unit vector.
        pair_m: the pair's separation.
    """
    ax, ay = away.tolist()
    r = math.hypot(ax, ay)
    if r == 0.0:
        return towards
    ax, ay = ax / r, ay / r
    tx, ty = -ay, ax  # along the disc, one way or the other
    side = 1.0 if tx * towards[0] + ty * towards[1] >= 0.0 else -1.0
    tx, ty = side * tx, side * ty
    radius = ROUND_AT * pair_m
    if r > radius:  # the tangent: at asin(radius / r) off the line to the unit at rest, on that side
        sin_a = radius / r
        cos_a = math.sqrt(max(1.0 - sin_a * sin_a, 0.0))
        return (-ax * cos_a + tx * sin_a, -ay * cos_a + ty * sin_a)
    radial = min((radius - r) / pair_m, 1.0)  # inside the disc: back out onto it as it goes round
    vx, vy = tx + radial * ax, ty + radial * ay
    v = math.hypot(vx, vy)
    return (vx / v, vy / v)


def back_off_vector(away: np.ndarray, push: tuple[float, float] | list[float]) -> tuple[float, float]:
    """Aside from the other unit and away from it (``ASIDE`` times as much aside), and from every other
    unit as the push says.

    Aside is to the left as seen from the other unit: head on, the two no longer share a line.  Mostly
    aside: the ground a back-off gives is ground its unit must win back before the deadlock is cleared
    (at 45 degrees, 21 m of a 30 m back-off; at ``ASIDE`` 2, 13 m), and aside is what clears the line
    between the two.
    """
    ax, ay = away.tolist()
    norm = math.hypot(ax, ay)
    ax, ay = (ax / norm, ay / norm) if norm > 0.0 else (-1.0, 0.0)
    px, py = push
    vx, vy = ax - ASIDE * ay - px, ay + ASIDE * ax - py
    v = math.hypot(vx, vy)
    return (vx / v, vy / v) if v > 0.0 else (0.0, 0.0)


def aside_vector(rel: np.ndarray, way: tuple[float, float]) -> tuple[float, float]:
    """Out of the way ``way`` of another unit, square to it, on the side ``rel`` (from that unit) lies.

    Dead ahead, to the left as seen along ``way``.
    """
    wx, wy = way
    norm = math.hypot(wx, wy)
    if norm == 0.0:
        return (0.0, 0.0)
    wx, wy = wx / norm, wy / norm
    rx, ry = rel.tolist()
    side = -wy * rx + wx * ry  # along the left of ``way``
    return (-wy, wx) if side >= 0.0 else (wy, -wx)


def meet(rel: np.ndarray, closing: np.ndarray, pair_s: np.ndarray) -> np.ndarray:
    """Whether each pair's paths meet: the gap ``rel`` (to the other) shrinks under the other's way less
    one's own (``closing``, both at one speed), and at its closest it is within the pair's separation.

    Right of way is for units that would meet in a gap, not for neighbours going side by side (their
    gap holds; the push and ``_short`` keep it), nor for two whose paths pass wide of each other.
    """
    rate = (rel * closing).sum(axis=1)
    w2 = (closing * closing).sum(axis=1)
    least2 = (rel * rel).sum(axis=1) - rate * rate / np.where(w2 > 0.0, w2, 1.0)
    meet: np.ndarray = (rate < 0.0) & (least2 < pair_s * pair_s)
    return meet


def held(d: Direction, vec: tuple[float, float], reach_m: float, reason: str) -> Direction:
    """``d`` as a yielding unit's direction: along ``vec`` (``(0, 0)``: holding) for at most ``reach_m``."""
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


def resolving(hold: Hold, status: DirectionStatus | None) -> str:
    """The reason a resolving unit's direction gives."""
    if hold.round:
        what = status.value if status is not None else "at rest"
        return (
            f"going round {hold.other} ({what}), which stands in the way, to clear a deadlock;"
            f" goes on once past it, within {hold.until - hold.since:g} s"
        )
    return f"backing off from {hold.other} to clear a deadlock; goes on after {hold.until - hold.since:g} s"


def event(
    mover: str,
    blocker: str,
    at: np.ndarray,
    held_s: float,
    for_s: float,
    round_: bool,
    status: DirectionStatus | None,
    facing: bool = False,
    rounds: bool = False,
    rounding: str | None = None,
) -> DeadlockEvent:
    """The deadlock's event: who resolves it (``unit``), with whom, and how long at most (``backoff_s``).

    ``facing``: two units each cut to nothing by the other (``Facing``); ``rounds``: both going round
    units at rest; ``rounding``: the one of the two going round one (found at once).
    """
    x, y = at.tolist()
    if facing and rounds:
        why = f"{mover} and {blocker}, each going round a unit at rest, stop each other: {mover} gives way"
    elif facing and rounding is not None:
        why = (
            f"{mover} and {blocker}, each cut to nothing by the other, {rounding} going round a unit at rest:"
            f" {mover} gives way"
        )
    elif facing:
        why = f"{mover} and {blocker}, each cut to nothing by the other for {held_s:.0f} s: {mover} gives way"
    elif round_:
        what = status.value if status is not None else "at rest"
        why = f"{mover} came no nearer its goal for {held_s:.0f} s against {blocker} ({what}): goes round it"
    else:
        why = f"held {held_s:.0f} s, {blocker} not drawing away: {mover} backs off"
    why += f" for at most {for_s:g} s"
    return DeadlockEvent(
        unit=mover, other=blocker, position=(x, y), held_s=held_s, backoff_s=for_s, reason=why
    )
