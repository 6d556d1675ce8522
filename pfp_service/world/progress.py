"""The progress watch: what a unit's own reports show of its motion, said as what it is.

In the manner of Nav2's progress checker, a unit told to move that has not
left a circle of ``RADIUS_M`` in ``WINDOW_S`` seconds is ``stalled``; a
unit that says it is stopped (``speed_mps`` 0) is ``holding``.  Neither is a
fact of the field: the watch never starts an escape and never changes a
route (``core.tracking``), it only tells the unit, the map and the operator.

Time is the unit's own (``UnitState.t``) when it sends one and it runs
forward, else the planner's receive time.  The watch also measures the
unit's speed over the ground, over at least ``SPEED_BASE_S`` seconds so a
few metres of GPS noise between close reports do not read as speed, for a
unit that does not report ``speed_mps``: the stepper's pursuit point lies a
few seconds of driving ahead (``Stepper.pace``).  Bounded: a few numbers and
a ring of ``RING`` fixes per unit.  Pure values: no clock.
"""

from __future__ import annotations

import math
from collections import deque

from pfp_service.wire import Progress

__all__ = ["GAP_S", "RADIUS_M", "RING", "SPEED_BASE_S", "WINDOW_S", "ProgressWatch"]

WINDOW_S = 10.0  # Nav2's progress checker: 0.5 m in 10 s; a unit's fix jitters more, hence RADIUS_M
RADIUS_M = 2.0
SPEED_BASE_S = 2.0
GAP_S = 5.0  # fixes further apart than this are not measured across
RING = 64  # fixes kept for the speed: at 20 Hz, 3 s


class ProgressWatch:
    """One unit's watch: fed every report, read by the unit's direction."""

    __slots__ = ("_anchor", "_fixes", "_last_t", "_offset", "speed_mps", "verdict")

    def __init__(self) -> None:
        self._anchor: tuple[float, float, float] | None = None  # (t, x, y) where the unit last moved from
        self._fixes: deque[tuple[float, float, float]] = deque(maxlen=RING)
        self._last_t = -math.inf
        self._offset: float | None = None  # the unit's clock minus the planner's, when it sends one
        self.speed_mps = 0.0
        self.verdict = Progress.UNKNOWN

    def report(
        self,
        x: float,
        y: float,
        t: float | None,
        now: float,
        speed_mps: float | None,
        told_to_move: bool,
    ) -> Progress:
        """Take one report; returns (and keeps) the verdict for the direction that answers it.

        Args:
            x, y: where the unit says it is, metres.
            t: the unit's time of the fix, if it sent one.
            now: the planner's time of receipt.
            speed_mps: the unit's own speed, if it sent one.
            told_to_move: its last direction was to move (en route or escaping, with room to).
        """
        # per unit and report on the live tick (bench row: `pfp bench service`): the common cases
        # spelt inline, each verdict kept and returned in one step
        if t is None:
            at = now
        else:
            offset = self._offset
            at = (
                t - offset
                if offset is not None and abs((t - now) - offset) <= WINDOW_S
                else self._time(t, now)
            )
        if at < self._last_t:  # a clock that ran back (a restarted unit): start afresh
            self._fixes.clear()
            self._anchor = None
        self._last_t = at
        fix = (at, x, y)
        self._fixes.append(fix)
        # the unit's own speed taken as it comes, else measured
        if speed_mps is not None and speed_mps >= 0.0:
            self.speed_mps = speed_mps
            if speed_mps == 0.0:
                self._anchor = fix
                verdict = self.verdict = Progress.HOLDING
                return verdict
        else:
            self.speed_mps = self._speed(speed_mps)
        anchor = self._anchor
        if not told_to_move or anchor is None or (x - anchor[1]) ** 2 + (y - anchor[2]) ** 2 > RADIUS_M**2:
            self._anchor = fix
            verdict = Progress.MOVING if told_to_move and anchor is not None else Progress.UNKNOWN
        else:
            verdict = Progress.STALLED if at - anchor[0] >= WINDOW_S else Progress.MOVING
        self.verdict = verdict
        return verdict

    def _time(self, t: float | None, now: float) -> float:
        """The fix's time: the unit's, when it sends one and it runs on; else the time of receipt."""
        if t is None or not math.isfinite(t):
            return now
        if self._offset is None or abs((t - now) - self._offset) > WINDOW_S:
            self._offset = t - now  # its clock, mapped once, and again if it jumps
        return t - self._offset

    def _speed(self, reported: float | None) -> float:
        """The unit's speed: its own when it sends one; else measured over at least ``SPEED_BASE_S``."""
        if reported is not None and math.isfinite(reported):
            return max(reported, 0.0)
        t1, x1, y1 = self._fixes[-1]
        later = t1
        for t0, x0, y0 in reversed(self._fixes):
            if later - t0 > GAP_S:  # silent meanwhile: the gap says nothing of its speed
                break
            if t1 - t0 >= SPEED_BASE_S:
                return math.hypot(x1 - x0, y1 - y0) / (t1 - t0)
            later = t0
        return self.speed_mps
