"""Team previews: a team's members replayed together from their current states, by the live world's own code.

One stepper, two drivers.  The replay is a ``World`` of the team's members
alone, seeded with what the live world holds of them (``seed``: their
positions, reported speeds, missions and steppers, mid-escape included; the
team and its lead's track so far; the threats and zones in force, with the
time they have left) and driven on a simulated clock (``replay``).  Every
``dt_s`` each member moves as the fleet's simulated vehicles do
(``pfp_clients.sim.SimUnit``: ``speed_mps * dt_s`` along its newest
direction, no further than the direction's ``reach_m`` nor past its goal,
and only while en route or escaping) and reports where it is; the world
answers with the directions its team book judged (the lead's standoff and
waiting, the follower's cleared corridor, the controller's link) and its
dispersion between the members.  So the tracks are what the live stream
would drive for vehicles moving at their reported speeds (a member that
reports none: the request's ``speeds``, else its mobility's ``speed_mps``).

Units outside the team whose reach comes within dispersion distance of the
team's (``team_outsiders``: at most ``MAX_PREVIEW_OUTSIDERS``, nearest first)
are replayed with it by the same rules: one the planner guides and that
reports a speed moves toward its own goal, on a stepper started afresh where
it is (a copy of each live one would cost the loop more than the rest of the
seed); any other stands where it is.  The reply names them and counts those
left out.

What the replay does not hold: a deliberation's latency (its escape searches
land at once, ``deliberation="inline"``), each unit's progress watch and
right-of-way holds, which start afresh (its first replayed reports judge
whether it moves), an outsider's own team (it is replayed as a lone unit),
and under ``--cluster`` the missions of units another planner guides (they
stand where they are).

Sans-I/O: ``seed`` reads the live world; ``replay`` takes a seed, a clock and
a budget (checked at every step) and returns a ``TeamPreview``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
from collections.abc import Callable
from typing import TypeVar

import msgspec

from pfp_service.core.params import Resolved
from pfp_service.core.stepper import Stepper
from pfp_service.errors import InputError
from pfp_service.wire import (
    Direction,
    DirectionStatus,
    Goal,
    GoalMobility,
    RejectedEvent,
    ThreatUpdate,
    UnitKind,
    UnitState,
)
from pfp_service.wire.messages import (
    MAX_PREVIEW_MEMBERS,
    MemberTrack,
    StatusChange,
    TeamPreview,
    TeamPreviewRequest,
    TeamUpdate,
    ZoneUpdate,
)
from pfp_service.world.events import (
    Input,
    MissionRestored,
    StateReported,
    TeamPut,
    ThreatPut,
    WorldSettings,
    ZonePut,
)
from pfp_service.world.mobility import own_speed
from pfp_service.world.team_outsiders import guided as outsider_guided
from pfp_service.world.team_outsiders import nearby, reach
from pfp_service.world.units import TRANSITIONS, Started, Step, UnitRecord
from pfp_service.world.world import World

__all__ = ["MAX_REPLY_POINTS", "MemberSeed", "TeamSeed", "replay", "seed"]

# Track points in one reply, all members together, at cm and ms: a longer replay is thinned evenly
# (each point is about 25 bytes of JSON, and a reply must fit the wire's 256 KiB).
MAX_REPLY_POINTS = 4_000
MAX_STATUS_CHANGES = 1_024  # all members together: a reason that keeps changing is cut, not the reply's size
_MOVING = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)
_NUMBERS = re.compile(r"-?\d+(\.\d+)?")
Point = tuple[float, float]
_KINDS = frozenset(k.value for k in UnitKind)
_M = TypeVar("_M", ThreatUpdate, ZoneUpdate)


@dataclasses.dataclass(frozen=True)
class MemberSeed:
    """One member as the live world holds it: detached copies, safe to send to a worker."""

    unit: str
    position: Point | None
    speed_mps: float  # as last reported or measured (0: stopped, or never said)
    kind: str | None = None
    goal: Goal | None = None
    origin: Point | None = None
    stepper: Stepper | None = None
    status: DirectionStatus | None = None  # its last direction's
    direction: Direction | None = None  # as the team book last judged it: what it moves on now
    # an outsider's mission: its stepper starts afresh in the replay (copying 64 on the loop costs more
    # than all the rest of a seed)
    params: Resolved | None = None
    mobility: GoalMobility | None = None  # the class its states name (``world.mobility``): replayed with it


@dataclasses.dataclass(frozen=True)
class TeamSeed:
    """What a team preview replays from: the team, its members, the lead's track, and the world they are in."""

    team_id: str
    team: TeamUpdate
    members: tuple[MemberSeed, ...]
    track: tuple[Point, ...]  # the lead's track since the team was put (the cleared corridor's spine)
    held: frozenset[str]  # members the team book held at their last direction (a hold is not a stop)
    settings: WorldSettings
    threats: tuple[tuple[str, ThreatUpdate], ...]  # each with ``ttl_s`` the time it has left
    zones: tuple[tuple[str, ZoneUpdate], ...]
    outsiders: tuple[MemberSeed, ...] = ()  # units outside the team near its reach, nearest first
    left_out: int = 0  # how many more were near but past ``MAX_PREVIEW_OUTSIDERS``


def seed(
    world: World, team_id: str, now: float, request: TeamPreviewRequest | None = None
) -> TeamSeed | None:
    """What the live ``world`` holds of team ``team_id`` at ``now``, and of the units near it; ``None``: no such team.

    ``request``'s horizon and speeds bound the members' reaches (``team_outsiders``).

    Raises:
        InputError: the team has more members than a preview replays (``MAX_PREVIEW_MEMBERS``).
    """
    team = world.teams.teams.get(team_id)
    if team is None:
        return None
    units = team.units()
    if len(units) > MAX_PREVIEW_MEMBERS:
        raise InputError(
            "$", f"team {team_id!r} has {len(units)} members; a preview replays {MAX_PREVIEW_MEMBERS}"
        )
    rec, sent = world.records, world.teams.sent
    members = []
    for u in sorted(units):
        r = rec.units.get(u)
        if r is None:
            members.append(MemberSeed(u, None, 0.0))
            continue
        members.append(_member(r, r.stepper is not None and r.goal is not None, sent.get(u), True))
    req = request or TeamPreviewRequest()
    reaches = [  # a member the replay does not move stands
        reach(m.position, m.goal.position if m.stepper is not None else None, _speed(m, req), req.horizon_s)  # type: ignore[union-attr]
        for m in members
        if m.position is not None
    ]
    near, left_out = nearby(rec.units, frozenset(units), reaches, world.settings.dispersion, req.horizon_s)
    outsiders = tuple(_member(rec.units[u], outsider_guided(rec.units[u]), None, False) for u in near)
    threats = tuple((tid, _left(t.update, t.expires_at, now)) for tid, t in sorted(rec.threats.items()))
    zones = tuple((zid, _left(z.update, z.expires_at, now)) for zid, z in sorted(rec.zones.items()))
    return TeamSeed(
        team_id,
        team,
        tuple(members),
        tuple(world.teams.tracks.get(team_id, ())),
        frozenset(world.teams.held & set(units)),
        world.settings,
        tuple((i, t) for i, t in threats if t is not None),
        tuple((i, z) for i, z in zones if z is not None),
        outsiders,
        left_out,
    )


def _member(r: UnitRecord, moves: bool, direction: Direction | None, stepper: bool) -> MemberSeed:
    """What the replay needs of ``r``: its mission only if it ``moves`` (else it stands), with a copy of its ``stepper``."""
    if not moves:
        # a member keeps its mission (it stands); an outsider stands without one
        goal, origin = (r.goal, r.origin) if stepper else (None, None)
        return MemberSeed(
            r.id,
            r.position,
            r.progress.speed_mps,
            r.kind,
            goal,
            origin,
            status=r.last_status,
            mobility=r.mobility,
        )
    assert r.stepper is not None
    copied = copy.deepcopy(r.stepper) if stepper else None
    return MemberSeed(
        r.id,
        r.position,
        r.progress.speed_mps,
        r.kind,
        r.goal,
        r.origin,
        copied,
        r.last_status,
        direction,
        None if stepper else r.stepper.params,
        r.mobility,
    )


def _left(msg: _M, expires_at: float | None, now: float) -> _M | None:
    """``msg`` with the time it has left as its TTL (``None``: it has expired)."""
    if expires_at is None:
        return msgspec.structs.replace(msg, ttl_s=None)
    left = expires_at - now
    return msgspec.structs.replace(msg, ttl_s=left) if left > 0.0 else None


@dataclasses.dataclass
class _Vehicle:
    """A simulated member: it moves along its newest direction at its speed, as ``SimUnit`` does."""

    seed: MemberSeed
    speed_mps: float
    at: Point
    status: DirectionStatus | None = None
    vector: Point = (0.0, 0.0)
    left_m: float = math.inf  # reach_m left of the newest direction
    to_goal_m: float | None = None
    track: list[tuple[float, float, float]] = dataclasses.field(default_factory=list)
    statuses: list[StatusChange] = dataclasses.field(default_factory=list)
    said: tuple[DirectionStatus, str] | None = None
    arrived_s: float | None = None
    max_changes: int = MAX_STATUS_CHANGES

    @property
    def kind(self) -> UnitKind | None:
        return UnitKind(self.seed.kind) if self.seed.kind in _KINDS else None

    def take(self, d: Direction | None, t_s: float) -> None:
        """Hold ``d`` as its newest direction (``None``: none came), noting a change of what it says."""
        if d is None:
            return
        self.status, self.vector = d.status, d.vector
        self.left_m = math.inf if d.reach_m is None else d.reach_m
        self.to_goal_m = d.distance_to_goal
        said = (d.status, _NUMBERS.sub("#", d.reason))
        if said != self.said and len(self.statuses) < self.max_changes:
            self.statuses.append(StatusChange(t_s=t_s, status=d.status, reason=d.reason))
        self.said = said
        if d.status is DirectionStatus.ARRIVED and self.arrived_s is None:
            self.arrived_s = t_s

    def advance(self, dt_s: float) -> None:
        if self.status not in _MOVING:
            return
        dist = min(self.speed_mps * dt_s, self.left_m)
        if self.to_goal_m is not None:
            dist = min(dist, self.to_goal_m)  # slow down at the goal rather than overshoot it
        norm = math.hypot(*self.vector)
        if norm > 0.0 and dist > 0.0:
            self.at = (self.at[0] + dist * self.vector[0] / norm, self.at[1] + dist * self.vector[1] / norm)
            self.left_m -= dist

    def report(self, t_s: float) -> StateReported:
        speed = self.speed_mps if self.status in _MOVING else 0.0  # as ``SimUnit.state`` says it
        return StateReported(
            self.seed.unit,
            UnitState(position=self.at, speed_mps=speed, kind=self.kind, mobility=self.seed.mobility),
        )


def _speed(m: MemberSeed, request: TeamPreviewRequest) -> float:
    """A member's speed in the replay: as it reported or was measured, else as the request gives it, else its
    mobility's own ``speed_mps`` (its goal's over its states': the speed it said it drives at), else 0."""
    if m.speed_mps > 0.0:
        return m.speed_mps
    given = request.speeds.get(m.unit)
    if given is not None:
        return given
    mob = m.goal.mobility if m.goal is not None and m.goal.mobility is not None else m.mobility
    own = own_speed(mob) if mob is not None else None
    return own if own is not None else 0.0


def replay(
    s: TeamSeed, request: TeamPreviewRequest | None, clock: Callable[[], float], budget_s: float
) -> TeamPreview:
    """Every member's track over time, as the live world would drive them, within ``budget_s`` on ``clock``.

    Raises:
        InputError: a member with a goal has no speed, reported, given or in its mobility (``$.speeds``).
    """
    req = request or TeamPreviewRequest()
    deadline = clock() + budget_s
    guided = [m for m in s.members if m.position is not None and m.goal is not None and m.stepper is not None]
    slow = [m.unit for m in guided if _speed(m, req) <= 0.0]
    if slow:
        raise InputError("$.speeds", f"{', '.join(slow)} reported no speed (stopped): give one in speeds")
    settings = dataclasses.replace(
        s.settings, deliberation="inline", origin=None, lookahead=0, threat_ttl_s=None, cluster=False
    )
    w = World(settings)
    ids = {m.unit for m in guided}
    cars = [_Vehicle(m, _speed(m, req), m.position, m.status) for m in s.members if m.position is not None]
    others = [
        _Vehicle(m, m.speed_mps if m.params is not None else 0.0, m.position, m.status)  # type: ignore[arg-type]
        for m in s.outsiders
    ]
    afresh = [m for m in s.outsiders if m.params is not None]
    first: list[Input] = [ThreatPut(i, t) for i, t in s.threats]
    first += [ZonePut(i, z) for i, z in s.zones]
    first.append(TeamPut(s.team_id, s.team))
    first += [car.report(0.0) for car in cars + others]
    first += [MissionRestored(m.unit, m.goal, m.origin or m.position, _params(m.stepper)) for m in guided]  # type: ignore[arg-type]
    first += [MissionRestored(m.unit, m.goal, m.origin or m.position, m.params) for m in afresh]  # type: ignore[arg-type]
    refused = [e for e in w.apply(first, 0.0).events if isinstance(e, RejectedEvent)]
    if refused:  # the live world took these: a replay that cannot is a fault, not a track
        raise RuntimeError(f"the replay refused {refused[0].key}: {refused[0].reason}")
    for m in guided:  # the live steppers, mid-escape included: the replay is their stream
        assert m.stepper is not None and m.origin is not None
        rec = w.records.units[m.unit]
        if (rec.phase, Step.STARTED) not in TRANSITIONS:  # judged arrived or trapped where it stands: as live
            continue
        w.records.book.started(rec, Started((m.goal, m.origin, m.stepper.params), copy.deepcopy(m.stepper)))  # type: ignore[arg-type]
    for c in others:  # an outsider's statuses and track are not in the reply
        c.max_changes = 0
    unsent = [c for c in cars if c.seed.direction is None]
    if unsent or others:  # not judged in the team (outsiders never are): the direction its next report gets
        again = {
            d.unit: d
            for d in w.apply([c.report(0.0) for c in (cars if unsent else []) + others], 0.0).directions
        }
        for c in unsent + others:
            c.take(again.get(c.seed.unit), 0.0)
    for c in cars:
        c.max_changes = max(8, MAX_STATUS_CHANGES // len(cars))
        c.take(c.seed.direction, 0.0)
        c.track.append((0.0, *c.at))
    w.teams.tracks[s.team_id] = list(s.track)
    w.teams.held = set(s.held)
    t, stopped = 0.0, "horizon"
    for k in range(1, math.ceil(req.horizon_s / req.dt_s) + 1):
        t = k * req.dt_s  # each member moves on the direction it holds, then reports, as the fleet's do
        for car in cars:
            car.advance(req.dt_s)
        for car in others:
            car.advance(req.dt_s)
        out = w.apply([car.report(t) for car in cars + others], t)
        by_unit = {d.unit: d for d in out.directions}
        for car in cars:
            car.take(by_unit.get(car.seed.unit), t)
            car.track.append((t, *car.at))
        for car in others:
            car.take(by_unit.get(car.seed.unit), t)
        if all(c.arrived_s is not None for c in cars if c.seed.unit in ids):
            stopped = "arrived"
            break
        if clock() > deadline:
            stopped = "budget"
            break
    arrivals = [c.arrived_s for c in cars if c.seed.unit in ids]
    eta = max(a for a in arrivals if a is not None) if arrivals and None not in arrivals else None
    return TeamPreview(
        team=s.team_id,
        eta_s=eta,
        members=_thinned(cars, s.members),
        simulated_s=t,
        stopped=stopped,
        outsiders=[m.unit for m in s.outsiders],
        outsiders_left_out=s.left_out,
    )


def _params(st: Stepper | None) -> Resolved:
    assert st is not None
    return st.params


def _thinned(cars: list[_Vehicle], members: tuple[MemberSeed, ...]) -> list[MemberTrack]:
    """One track per member (those never heard of: an empty one), thinned to ``MAX_REPLY_POINTS`` in all."""
    total = sum(len(c.track) for c in cars)
    every = max(1, math.ceil(total / MAX_REPLY_POINTS))
    by = {c.seed.unit: c for c in cars}
    out = []
    for m in members:
        c = by.get(m.unit)
        if c is None:
            out.append(MemberTrack(unit=m.unit))
            continue
        pts = c.track[::every]
        if pts[-1] is not c.track[-1]:
            pts.append(c.track[-1])
        pts = [(round(t, 3), round(x, 2), round(y, 2)) for t, x, y in pts]
        out.append(
            MemberTrack(
                unit=m.unit, speed_mps=c.speed_mps, points=pts, statuses=c.statuses, arrived_s=c.arrived_s
            )
        )
    return out
