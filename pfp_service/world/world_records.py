"""The world's records: one per unit, threat and keep-out zone, and the counts kept with them.

A unit's record holds what it reported, its goal and mission, its stepper,
its staleness, its last direction and push, and the deliberation job asked
for it.  The methods here are the record-keeping rules the world's decisions
are made of: a report makes a unit fresh, a unit goes stale or is forgotten,
a mission is dropped (its job superseded), a threat or a zone is put,
removed or expires.  The field in force carries the zones in force
(``ThreatField.with_zones``, as ``core.zones`` says): whatever takes the
field -- the stepper, deliberation jobs, previews -- sees them.  They return what changed; the world decides what goes out.  Pure
values: ``now`` is a parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import msgspec
import numpy as np

from pfp_service.core import Resolved, Stepper, Threat, ThreatField
from pfp_service.core.cull import MIN_THREATS, CullIndex
from pfp_service.core.params import FieldStats, field_stats
from pfp_service.core.zones import Zone, ZoneSet
from pfp_service.wire import Direction, DirectionStatus, Goal, Mission, ThreatUpdate
from pfp_service.wire.messages import ZoneUpdate
from pfp_service.world.events import Job, unit_key
from pfp_service.world.progress import ProgressWatch
from pfp_service.world.terrain import Ground, ground_zones, sight_of

__all__ = ["Records", "ThreatRecord", "UnitRecord", "ZoneRecord"]


@dataclass(slots=True)
class UnitRecord:
    id: str
    key: int
    position: tuple[float, float] | None = None
    seq: int | None = None
    kind: str | None = None
    last_seen: float = -math.inf
    goal: Goal | None = None
    origin: tuple[float, float] | None = None  # x0: where the unit was when its goal was set
    stepper: Stepper | None = None
    epoch: int = 0  # bumped by every goal set or cancelled
    stale: bool = False
    stale_since: float | None = None
    token_gone_since: float | None = None
    silence_timer: bool = False
    last_status: DirectionStatus | None = None
    last_reason: str = ""
    last_distance: float | None = None
    last_vector: tuple[float, float] | None = None
    job: Job | None = None
    push: Direction | None = None  # the last push, until a report is answered
    push_tries: int = 0
    owned: bool = True  # this planner guides it (scale-out: rendezvous over the live planners)
    shared: tuple[Goal, tuple[float, float], Resolved] | None = None  # a mission another planner fixed
    progress: ProgressWatch = field(default_factory=ProgressWatch)  # what its reports show of its motion

    def token(self) -> tuple[int, int]:
        """What a deliberation result must match to be adopted: the goal's epoch and the world's version."""
        return (self.epoch, self.stepper.version if self.stepper is not None else -1)

    def live(self) -> bool:
        """Whether the unit is told directions: it has reported, is not stale, and this planner guides it."""
        return self.position is not None and not self.stale and self.owned


@dataclass(slots=True)
class ThreatRecord:
    update: ThreatUpdate
    threat: Threat
    expires_at: float | None
    row: np.ndarray | None = None  # the threat's packed row in the field, once packed (``Records.field``)


@dataclass(slots=True)
class ZoneRecord:
    update: ZoneUpdate
    zone: Zone
    expires_at: float | None


class Records:
    """Every unit and threat the world holds, the counts kept as they change, and the field of the threats."""

    def __init__(self, intensity: str = "peak", ground: Ground | None = None) -> None:
        self.units: dict[str, UnitRecord] = {}
        self.threats: dict[str, ThreatRecord] = {}
        self.zones: dict[str, ZoneRecord] = {}
        self.stale = 0  # units stale
        self.deliberating = 0  # units with a job asked and not answered
        self.superseded: list[Job] = []  # jobs asked and no longer wanted, until the world says so
        self.intensity = intensity
        self._bare: ThreatField | None = None  # the threats' field, built when asked, until they change
        self._field: ThreatField | None = None  # ... and with the zones: until the threats or zones change
        self._zone_set: ZoneSet | None = None  # built when asked, until the zones change
        self.cull: CullIndex | None = None
        self._stats: FieldStats | None = None  # the threats' ``field_stats``: at first use, until they change
        self.sight, self._barriers = (
            sight_of(ground),
            ground_zones(ground),
        )  # the terrain's (``world.terrain``)

    @property
    def field(self) -> ThreatField:
        """The field of the threats in force, in id order, with its cull index and stats, and the zones."""
        if self._field is None:
            if self._bare is None:  # a zone change keeps the threats' field, its cull index and stats
                ordered = [self.threats[k] for k in sorted(self.threats)]
                for t in ordered:  # a threat put packs its row; the others keep theirs
                    if t.row is None:
                        t.row = ThreatField([t.threat], self.intensity, sight=self.sight).packed[0]  # type: ignore[arg-type]
                threats, rows = [t.threat for t in ordered], [t.row for t in ordered]
                self._bare = ThreatField.from_rows(threats, rows, self.intensity)  # type: ignore[arg-type]
                self._bare.sight = self.sight  # a worker rebuilds the field from its threats with it
                self.cull = CullIndex(self._bare.packed) if len(ordered) >= MIN_THREATS else None
                self._stats = None  # a wave changes the threats and starts no mission: ``stats`` when asked
            self._field = self._bare.with_zones(self.zone_set) if self.zones or self._barriers else self._bare
        return self._field

    @property
    def stats(self) -> FieldStats | None:
        """The threats' ``field_stats`` (``resolve``'s figures), computed at first use; ``None`` before ``field``."""
        if self._stats is None and self._bare is not None:
            self._stats = field_stats(self._bare.threats)
        return self._stats

    @property
    def zone_set(self) -> ZoneSet:
        """The zones in force, in id order (``core.zones.ZoneSet``)."""
        if self._zone_set is None:
            self._zone_set = ZoneSet([*self._barriers, *(self.zones[k].zone for k in sorted(self.zones))])
        return self._zone_set

    # -- units ------------------------------------------------------------------------
    def add(self, unit_id: str, owned: bool, now: float, reported: bool) -> UnitRecord:
        """A new unit's record; one made by anything but a report is stale from the start."""
        rec = self.units[unit_id] = UnitRecord(unit_id, unit_key(unit_id), owned=owned)
        if not reported:
            rec.stale = True
            rec.stale_since = now
            self.stale += 1
        return rec

    def heard(
        self, rec: UnitRecord, position: tuple[float, float], seq: int | None, kind: str | None, now: float
    ) -> None:
        """A report: where the unit is, and proof of life whatever its token says; its push is answered."""
        rec.position = position
        rec.seq = seq
        rec.kind = kind if kind is not None else rec.kind
        rec.last_seen = now
        if rec.stale:
            rec.stale = False
            rec.stale_since = None
            self.stale -= 1
        rec.token_gone_since = None
        rec.push = None

    def go_stale(self, rec: UnitRecord, now: float) -> bool:
        """Mark a unit that has reported stale; whether it was fresh until now."""
        if rec.stale or rec.position is None:
            return False
        rec.stale = True
        rec.stale_since = now
        self.stale += 1
        return True

    def forgettable(self, rec: UnitRecord, now: float, limit_s: float | None) -> bool:
        """Whether a unit has been stale for ``limit_s`` (``None``: never forgotten)."""
        return (
            rec.stale
            and rec.stale_since is not None
            and limit_s is not None
            and now - rec.stale_since >= limit_s
        )

    def forget(self, rec: UnitRecord) -> None:
        """Drop a unit's record, and its job with it."""
        self.supersede(rec)
        if self.units.pop(rec.id, None) is not None and rec.stale:
            self.stale -= 1

    def supersede(self, rec: UnitRecord) -> Job | None:
        """The unit's job (if any) no longer counts: a newer goal or world is in force.  Returns that job.

        The job is noted in ``superseded``: whoever runs it may drop it (``Outputs.cancelled``).
        """
        job = rec.job
        if job is not None:
            self.superseded.append(job)
            rec.job = None
            self.deliberating -= 1
        return job

    def asked(self, rec: UnitRecord, job: Job) -> None:
        """A deliberation job was asked for the unit."""
        rec.job = job
        self.deliberating += 1

    def answered(self, rec: UnitRecord) -> str:
        """The unit's job came back; returns its kind."""
        assert rec.job is not None
        kind = rec.job.kind
        rec.job = None
        self.deliberating -= 1
        return kind

    def drop_mission(self, rec: UnitRecord) -> None:
        """The unit's goal, mission, stepper and last verdict go; a new epoch starts, and its job is superseded."""
        rec.goal = None
        rec.stepper = None
        rec.origin = None
        rec.last_status = None
        rec.last_reason = ""
        rec.last_distance = None
        rec.last_vector = None
        rec.shared = None
        rec.epoch += 1
        self.supersede(rec)

    def share(self, rec: UnitRecord, mission: Mission) -> None:
        """Another planner fixed the unit's mission: kept for when this one takes the unit over."""
        params = Resolved(**msgspec.structs.asdict(mission.params))
        rec.shared = (mission.goal, (mission.origin[0], mission.origin[1]), params)

    def hand_over(self, rec: UnitRecord) -> None:
        """Another planner guides the unit now: this one keeps its mission, not its stepper."""
        rec.owned = False
        self.supersede(rec)
        rec.stepper = None
        rec.push = None
        rec.last_status = None

    def counts(self) -> dict[str, int]:
        """The figures of the status reply these records keep (O(1) but ``units_owned``)."""
        return {
            "units": len(self.units),
            "units_stale": self.stale,
            "threats": len(self.threats),
            "zones": len(self.zones),
            "deliberating": self.deliberating,
            "units_owned": sum(1 for r in self.units.values() if r.owned),
        }

    # -- threats ----------------------------------------------------------------------
    def put_threat(self, tid: str, record: ThreatRecord) -> ThreatRecord | None:
        """Put a threat; returns the one it replaces, if any."""
        old = self.threats.get(tid)
        self.threats[tid] = record
        self._bare = self._field = None
        return old

    def remove_threat(self, tid: str) -> ThreatRecord | None:
        self._bare = self._field = None
        return self.threats.pop(tid, None)

    def expire(self, tid: str, now: float) -> ThreatRecord | None:
        """Remove a threat whose TTL has run out at ``now`` (one put again since is kept); returns it."""
        t = self.threats.get(tid)
        if t is None or t.expires_at is None or t.expires_at > now:
            return None
        self._bare = self._field = None
        return self.threats.pop(tid)

    # -- zones --------------------------------------------------------------------------
    def _zones_changed(self) -> None:
        self._zone_set = None
        self._field = None

    def put_zone(self, zid: str, record: ZoneRecord) -> ZoneRecord | None:
        """Put a zone; returns the one it replaces, if any."""
        old = self.zones.get(zid)
        self.zones[zid] = record
        self._zones_changed()
        return old

    def remove_zone(self, zid: str) -> ZoneRecord | None:
        gone = self.zones.pop(zid, None)
        if gone is not None:
            self._zones_changed()
        return gone

    def expire_zone(self, zid: str, now: float) -> ZoneRecord | None:
        """Remove a zone whose TTL has run out at ``now`` (one put again since is kept); returns it."""
        z = self.zones.get(zid)
        if z is None or z.expires_at is None or z.expires_at > now:
            return None
        return self.remove_zone(zid)
