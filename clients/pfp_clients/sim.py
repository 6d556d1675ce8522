"""Sans-I/O simulated vehicles: they report where they are and move along the directions they get.

A ``SimUnit`` never reads the clock or touches the network.  The fleet driver
asks it whether a report is due (``due``, at its own ``rate_hz``) and for a
``UnitState`` (which bumps ``seq``), hands it every ``Direction`` received,
and calls ``advance(dt_s, t_s)`` once per tick: it then moves
``speed_mps * dt_s`` along the newest direction -- never past the goal, and
never further than the direction's ``reach_m`` from where it reported in the
state the direction answers (its ``seq``) -- unless the planner said it is arrived, trapped or has no goal, or it is in
one of its ``stops``.  It behaves as a real vehicle does, not as the
planner's step: its own speed and report rate, its stops (reported as
``speed_mps`` 0), a fix off by a seeded Gaussian ``gps_sigma_m`` per
axis, and its mobility class on every state.  A direction that comes after the
vehicle has moved on from that report (sent again for the same report when
the world changed, or answered late) is a leg from where it reported: the
vehicle drives from where it is to the leg's end, ``reach_m`` along the
direction's ``vector`` from that report, and stops there, rather than taking
``reach_m`` afresh from where the direction found it (which would carry it
past ground the planner judged, out of a follower's cleared corridor).  Arrival is only ever what the planner reported (status ``arrived``
within its tolerance).
"""

from __future__ import annotations

import math
import random
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

from pfp_service.team import UnitSpec
from pfp_service.wire import Direction, DirectionStatus, GoalMobility, UnitState

__all__ = ["SimUnit", "TrackPoint"]

_MOVING = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)
_REPORTS_KEPT = 32  # the newest reports whose positions a direction's leg may start from


@dataclass(frozen=True, slots=True)
class TrackPoint:
    """Where a unit was at simulated time ``t_s`` (and at ``wall_s``, the driver's monotonic clock)."""

    t_s: float
    wall_s: float
    x: float
    y: float


@dataclass
class SimUnit:
    """One simulated vehicle following the planner's directions."""

    spec: UnitSpec
    position: tuple[float, float] = (0.0, 0.0)
    seq: int = 0
    direction: Direction | None = None
    arrived_at_s: float | None = None
    trapped_reason: str = ""
    replies: int = 0  # directions received
    track: list[TrackPoint] = field(default_factory=list)
    rate_hz: float = 5.0  # its reports per simulated second (the spec's, else the fleet's)
    gps_sigma_m: float = 0.0  # its fix's error, metres per axis (the spec's, else the fleet's)
    stops: tuple[tuple[float, float], ...] = ()  # (at_s, for_s): halts (the spec's, else the fleet's)
    mobility: GoalMobility | None = None  # its class on every state (the spec's, else the fleet's)
    seed: int = 0
    next_report_s: float = 0.0
    _rng: random.Random = field(init=False, repr=False)
    _left_m: float = field(default=math.inf, init=False, repr=False)  # reach_m left of the newest direction
    # seq -> the true position when it reported (the newest ``_REPORTS_KEPT``): where a direction's leg starts
    _reported: dict[int, tuple[float, float]] = field(default_factory=dict, init=False, repr=False)
    _aim: tuple[float, float] | None = field(default=None, init=False, repr=False)  # the newest leg's end

    def __post_init__(self) -> None:
        self.position = (float(self.spec.start[0]), float(self.spec.start[1]))
        if self.spec.rate_hz is not None:
            self.rate_hz = self.spec.rate_hz
        if self.spec.gps_sigma_m is not None:
            self.gps_sigma_m = self.spec.gps_sigma_m
        if self.spec.stops is not None:
            self.stops = tuple((s.at_s, s.for_s) for s in self.spec.stops)
        if self.spec.mobility is not None:
            self.mobility = self.spec.mobility.wire()
        self._rng = random.Random(zlib.crc32(self.spec.id.encode()) ^ (self.seed * 0x9E3779B1))

    def stopped(self, t_s: float) -> bool:
        """Whether it is halted at simulated time ``t_s`` (in one of its stops)."""
        return any(at <= t_s < at + dur for at, dur in self.stops)

    def due(self, t_s: float) -> bool:
        """Whether its next report is due at simulated time ``t_s`` (at its own rate); if so, the next is booked."""
        if t_s + 1e-9 < self.next_report_s:
            return False
        self.next_report_s = max(self.next_report_s + 1.0 / self.rate_hz, t_s)
        return True

    @property
    def id(self) -> str:
        return self.spec.id

    @property
    def status(self) -> str:
        """The planner's latest word on this unit, or ``waiting`` before the first direction."""
        return "waiting" if self.direction is None else self.direction.status.value

    @property
    def arrived(self) -> bool:
        return self.direction is not None and self.direction.status is DirectionStatus.ARRIVED

    @property
    def deliberating(self) -> bool:
        """The newest direction says a route is being computed off the planner's loop (plain descent until then)."""
        return self.direction is not None and self.direction.deliberating and not self.arrived

    @property
    def answered(self) -> int:
        """The ``seq`` of the newest direction received (-1 before any)."""
        d = self.direction
        return -1 if d is None or d.seq is None else d.seq

    def state(self, t_s: float) -> UnitState:
        """The next report: the current position (off by its GPS error) with a fresh ``seq``, and its speed."""
        self.seq += 1
        heading = None
        if self.direction is not None and self.direction.heading_deg is not None:
            heading = self.direction.heading_deg
        x, y = self.position
        self._reported[self.seq] = self.position
        if len(self._reported) > _REPORTS_KEPT:
            del self._reported[next(iter(self._reported))]  # the oldest
        if self.gps_sigma_m > 0.0:
            x += self._rng.gauss(0.0, self.gps_sigma_m)
            y += self._rng.gauss(0.0, self.gps_sigma_m)
        moving = self.direction is not None and self.direction.status in _MOVING and not self.stopped(t_s)
        return UnitState(
            position=(x, y),
            t=max(t_s, 0.0),
            seq=self.seq,
            kind=self.spec.kind,
            speed_mps=self.spec.speed_mps if moving else 0.0,
            heading_deg=heading,
            mobility=self.mobility,
        )

    def on_direction(
        self, d: Direction, t_s: float, show: Callable[[tuple[float, float]], str] | None = None
    ) -> str | None:
        """Take a direction; returns a line worth logging when the status changed, else ``None``.

        A direction answering an older ``seq`` than one already held is stale and ignored.
        ``show`` writes the unit's position in the line (``coords.Coords.point``: lat/lon with an origin).
        """
        if d.seq is not None and d.seq < self.answered:
            return None
        before = self.status
        self.direction = d
        self.replies += 1
        self._left_m = math.inf if d.reach_m is None else d.reach_m
        self._aim = self._leg_end(d)
        if d.status is DirectionStatus.ARRIVED:
            if self.arrived_at_s is None:
                self.arrived_at_s = t_s
        else:
            self.arrived_at_s = None  # a new goal, or the planner changed its mind
        self.trapped_reason = d.reason if d.status is DirectionStatus.TRAPPED else ""
        if d.status.value == before:
            return None
        x, y = self.position
        where = f"at {show(self.position)}" if show is not None else f"at ({x:.2f}, {y:.2f})"
        if d.status is DirectionStatus.ARRIVED:
            return f"{self.id} arrived {where}, {d.distance_to_goal or 0.0:.2f} m from its goal"
        if d.status is DirectionStatus.TRAPPED:
            return f"{self.id} trapped {where}: {d.reason}"
        return f"{self.id} {d.status.value} {where}" + (f" ({d.reason})" if d.reason else "")

    def _leg_end(self, d: Direction) -> tuple[float, float] | None:
        """Where ``d``'s leg ends: ``reach_m`` (or the goal, if nearer) along its vector from where the unit
        reported in the state ``d`` answers; ``None`` when that report is not known here or the leg has no end."""
        start = self._reported.get(d.seq) if d.seq is not None else None
        leg = math.inf if d.reach_m is None else d.reach_m
        if d.distance_to_goal is not None:
            leg = min(leg, d.distance_to_goal)
        vx, vy = d.vector
        norm = math.hypot(vx, vy)
        if start is None or not math.isfinite(leg) or norm == 0.0:
            return None
        return (start[0] + leg * vx / norm, start[1] + leg * vy / norm)

    def advance(self, dt_s: float, t_s: float, wall_s: float) -> None:
        """Move for ``dt_s`` along the newest direction and record the track point at ``t_s``."""
        d = self.direction
        if not self.track:
            self.track.append(TrackPoint(t_s - dt_s, wall_s, *self.position))
        if d is not None and d.status in _MOVING and not self.stopped(t_s - dt_s) and self._aim is not None:
            self._to_leg_end(d, self.spec.speed_mps * dt_s)
        elif d is not None and d.status in _MOVING and not self.stopped(t_s - dt_s):
            dist = min(self.spec.speed_mps * dt_s, self._left_m)  # never past how far the direction is good
            if d.distance_to_goal is not None:
                dist = min(dist, d.distance_to_goal)  # slow down at the goal rather than overshoot it
            vx, vy = d.vector
            norm = math.hypot(vx, vy)
            if norm > 0 and dist > 0:
                self.position = (self.position[0] + dist * vx / norm, self.position[1] + dist * vy / norm)
                self._left_m -= dist
        self.track.append(TrackPoint(t_s, wall_s, *self.position))

    def _to_leg_end(self, d: Direction, run_m: float) -> None:
        """Up to ``run_m`` straight toward the leg's end; none once it is there or no longer ahead along ``d``."""
        assert self._aim is not None
        dx, dy = self._aim[0] - self.position[0], self._aim[1] - self.position[1]
        gap = math.hypot(dx, dy)
        if gap <= 1e-9 or dx * d.vector[0] + dy * d.vector[1] <= 0.0:
            return  # at the leg's end, or past it along the direction: it goes no further, and never back
        dist = min(run_m, gap)
        self.position = (self.position[0] + dist * dx / gap, self.position[1] + dist * dy / gap)

    def path_length_m(self) -> float:
        return sum(math.hypot(b.x - a.x, b.y - a.y) for a, b in zip(self.track, self.track[1:]))
