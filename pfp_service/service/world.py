"""The live world model: units, goals, threats and expiry, with time passed in.

Sans-I/O, like the planning core: every method takes decoded messages and
``now`` (seconds on any monotonic clock) and returns what changed.  The Zenoh
node turns those results into puts; the tests drive it with plain numbers.

Rule 1: every decision about *who gets a fresh direction* lives here
(``apply_*`` return the unit ids that need one; ``expire`` the same).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from pfp_service.core import PlannerParams, Stepper, StepStatus, Threat, ThreatField, resolve
from pfp_service.core.stepper import Advice, advise_many
from pfp_service.errors import FINITE_LIMIT
from pfp_service.wire import Direction, DirectionStatus, Goal, ThreatUpdate, UnitState

__all__ = ["UnitRecord", "World", "WorldSettings"]

_STATUS = {
    StepStatus.EN_ROUTE: DirectionStatus.EN_ROUTE,
    StepStatus.ESCAPING: DirectionStatus.ESCAPING,
    StepStatus.ARRIVED: DirectionStatus.ARRIVED,
    StepStatus.TRAPPED: DirectionStatus.TRAPPED,
    # mission bounds are enforced on decode; a stepper verdict of these is a dead end all the same
    StepStatus.OUT_OF_BOUNDS: DirectionStatus.TRAPPED,
    StepStatus.INVALID: DirectionStatus.TRAPPED,
}


@dataclass(frozen=True)
class WorldSettings:
    """What the world model needs from the service configuration."""

    planner: PlannerParams = field(default_factory=PlannerParams)
    threat_ttl_s: float | None = None  # default TTL for threats that carry none
    unit_stale_s: float = 10.0  # silence after which a unit is stale
    liveliness_debounce_s: float = 2.0  # a token DELETE counts after this long
    lookahead: int = 5  # predicted positions per direction
    bounds: tuple[tuple[float, float], tuple[float, float]] | None = None  # mission bounds


@dataclass
class UnitRecord:
    """Everything the planner knows about one unit."""

    id: str
    position: tuple[float, float] | None = None
    seq: int | None = None
    kind: str | None = None
    last_seen: float = -math.inf
    goal: Goal | None = None
    origin: tuple[float, float] | None = None  # x0: where the unit was when the goal was set
    stepper: Stepper | None = None
    stale: bool = False
    token_gone_since: float | None = None
    last_status: DirectionStatus | None = None


@dataclass
class _ThreatRecord:
    threat: Threat
    expires_at: float | None


@dataclass
class World:
    """Units, goals and threats of one mission, and the steppers that guide the units."""

    settings: WorldSettings = field(default_factory=WorldSettings)
    units: dict[str, UnitRecord] = field(default_factory=dict)
    _threats: dict[str, _ThreatRecord] = field(default_factory=dict)
    _field: ThreatField | None = None

    # -- threats --------------------------------------------------------------
    @property
    def field(self) -> ThreatField:
        if self._field is None:
            ordered = [self._threats[k].threat for k in sorted(self._threats)]
            self._field = ThreatField(ordered, self.settings.planner.intensity)
        return self._field

    def view(self, unit_id: str) -> World:
        """A detached copy holding one unit and the threats in force, for previews off the lock."""
        units = {}
        if unit_id in self.units:
            rec = self.units[unit_id]
            units[unit_id] = dataclasses.replace(rec, stepper=copy.deepcopy(rec.stepper))
        return World(self.settings, units, dict(self._threats), self._field)

    def threat_ids(self) -> set[str]:
        return set(self._threats)

    def threat_list(self) -> list[Threat]:
        return list(self.field.threats)

    def apply_threat(self, threat_id: str, msg: ThreatUpdate, now: float) -> set[str]:
        """A threat appeared or moved.  Returns the units that need a fresh direction."""
        threat = msg.to_threat(threat_id)
        ttl = msg.ttl_s if msg.ttl_s is not None else self.settings.threat_ttl_s
        self._threats[threat_id] = _ThreatRecord(threat, None if ttl is None else now + ttl)
        return self._world_changed()

    def remove_threat(self, threat_id: str) -> set[str]:
        if self._threats.pop(threat_id, None) is None:
            return set()
        return self._world_changed()

    # -- units ----------------------------------------------------------------
    def _unit(self, unit_id: str) -> UnitRecord:
        rec = self.units.get(unit_id)
        if rec is None:
            rec = self.units[unit_id] = UnitRecord(unit_id)
        return rec

    def apply_state(self, unit_id: str, msg: UnitState, now: float) -> set[str]:
        """A unit reported where it is.  It always gets a direction back (or ``no_goal``)."""
        rec = self._unit(unit_id)
        rec.position = (msg.position[0], msg.position[1])
        rec.seq = msg.seq
        rec.kind = msg.kind.value if msg.kind is not None else rec.kind
        rec.last_seen = now
        rec.stale = False
        rec.token_gone_since = None  # a report is proof of life, whatever the token says
        if rec.goal is not None and rec.stepper is None:
            self._start(rec)
        return {unit_id}

    def apply_goal(self, unit_id: str, msg: Goal, now: float) -> set[str]:
        rec = self._unit(unit_id)
        rec.goal = msg
        rec.stepper = None
        rec.origin = None
        rec.last_status = None
        if rec.position is not None:
            self._start(rec)
        return {unit_id} if rec.position is not None and not rec.stale else set()

    def cancel_goal(self, unit_id: str) -> set[str]:
        rec = self.units.get(unit_id)
        if rec is None or rec.goal is None:
            return set()
        rec.goal = None
        rec.stepper = None
        rec.origin = None
        rec.last_status = None
        return {unit_id} if rec.position is not None and not rec.stale else set()

    def liveliness(self, unit_id: str, alive: bool, now: float) -> None:
        rec = self._unit(unit_id)
        rec.token_gone_since = None if alive else now

    def expire(self, now: float) -> tuple[set[str], list[str], list[str]]:
        """Drop expired threats and mark silent or departed units stale.

        Returns:
            ``(needs_direction, expired_threat_ids, newly_stale_unit_ids)``.
        """
        expired = [k for k, r in self._threats.items() if r.expires_at is not None and r.expires_at <= now]
        dirty: set[str] = set()
        for k in expired:
            del self._threats[k]
        if expired:
            dirty = self._world_changed()
        stale = []
        s = self.settings
        for rec in self.units.values():
            if rec.stale or rec.position is None:  # never reported: nothing to go stale
                continue
            gone = rec.token_gone_since is not None and now - rec.token_gone_since >= s.liveliness_debounce_s
            silent = now - rec.last_seen > s.unit_stale_s
            if gone or silent:
                rec.stale = True
                stale.append(rec.id)
        dirty -= set(stale)
        return dirty, expired, stale

    # -- planning -------------------------------------------------------------
    def params_for(self, goal: Goal) -> PlannerParams:
        """The unit's planner parameters: service defaults, then the goal's overrides."""
        return self.settings.planner.merged(delta=goal.delta, tolerance=goal.tolerance, step=goal.step)

    def _start(self, rec: UnitRecord) -> None:
        assert rec.goal is not None and rec.position is not None
        rec.origin = rec.position
        goal = (rec.goal.position[0], rec.goal.position[1])
        resolved = resolve(self.params_for(rec.goal), rec.origin, goal, self.threat_list())
        rec.stepper = Stepper(rec.origin, goal, resolved, self.settings.bounds)

    def _world_changed(self) -> set[str]:
        self._field = None
        dirty = set()
        for rec in self.units.values():
            if rec.stepper is not None:
                rec.stepper.world_changed()
            if rec.goal is not None and rec.position is not None and not rec.stale:
                dirty.add(rec.id)
        return dirty

    def directions(self, unit_ids: set[str] | list[str]) -> list[Direction]:
        """A fresh direction for each unit named (stale and unknown units are skipped).

        Units with a goal are advised in one vectorised call; the rest get ``no_goal``.
        """
        out: list[Direction] = []
        guided: list[UnitRecord] = []
        for uid in sorted(unit_ids):
            rec = self.units.get(uid)
            if rec is None or rec.stale or rec.position is None:
                continue
            if rec.stepper is None:
                out.append(
                    Direction(unit=uid, seq=rec.seq, status=DirectionStatus.NO_GOAL, vector=(0.0, 0.0))
                )
            else:
                guided.append(rec)
        if not guided:
            return out
        field = self.field
        steppers = [r.stepper for r in guided]
        positions = np.array([r.position for r in guided], dtype=float)
        advices = advise_many(steppers, field, positions)  # type: ignore[arg-type]
        for rec, adv in zip(guided, advices):
            out.append(self._direction(rec, adv, field))
        return out

    def _direction(self, rec: UnitRecord, adv: Advice, field: ThreatField) -> Direction:
        assert rec.stepper is not None and rec.position is not None
        status = _STATUS[adv.status]
        rec.last_status = status
        heading = None
        if not adv.status.terminal:
            heading = math.degrees(math.atan2(adv.dx, adv.dy)) % 360.0
        return Direction(
            unit=rec.id,
            seq=rec.seq,
            status=status,
            vector=(adv.dx, adv.dy),
            heading_deg=heading,
            distance_to_goal=adv.distance,
            threat_level=min(max(adv.level, 0.0), FINITE_LIMIT),  # the wire's bound, even for absurd weights
            lookahead=self._lookahead(rec.stepper, field, rec.position, adv),
            reason=adv.reason,
        )

    def _lookahead(
        self, stepper: Stepper, field: ThreatField, pos: tuple[float, float], adv: Advice
    ) -> list[tuple[float, float]]:
        """The next positions the same stepper predicts, moving ``step`` each time."""
        n = self.settings.lookahead
        if n <= 0 or adv.status.terminal:
            return []
        ghost = copy.deepcopy(stepper)
        # a prediction, not a plan: a ghost that meets a new trap stops there instead of searching
        ghost.params = dataclasses.replace(ghost.params, escape="none")
        step = stepper.params.step
        x, y = pos[0] + step * adv.dx, pos[1] + step * adv.dy
        points = [(x, y)]
        while len(points) < n:
            a = ghost.advise(field, x, y)
            if a.status.terminal:
                break
            x, y = x + step * a.dx, y + step * a.dy
            points.append((x, y))
        return points
