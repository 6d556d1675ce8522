"""The live world: a sans-I/O state machine of one mission's units, goals and threats.

In the manner of h11's connection: ``World.apply(inputs, now)`` takes a batch
of frozen input events (``Input``) and returns ``Outputs``: the directions to
publish, the events to send and the deliberation jobs to run.  It never reads
a clock, opens a socket or touches a file; ``now`` is seconds on any
monotonic clock.

Rule 1: every decision lives here -- who gets a fresh direction, which event
fires and why, status transitions, staleness, expiry, limits.  The node only
decodes, enqueues, applies and publishes; it never reads the world's records.

The reactive part of ``apply`` is bounded: plain steepest descent for the
units touched, in one vectorised call (culled, ``core.cull``), plus their
look-ahead points (``plan.predict_many``: batched kernel steps, ghosts for
units on a route).  Everything unbounded -- ``auto``'s trap
look-ahead and the escape-route searches -- is *deliberation*: with
``deliberation="deferred"`` a unit's stepper records what it needs, the world
emits a ``Job`` holding a detached copy, and the driver runs ``job.run()``
anywhere and feeds back the ``Deliberated`` input it returns.  A result is
adopted only if it was computed for the unit's goal and world version still
in force (latest wins); until then the unit gets plain descent with
``deliberating`` set.  ``"inline"`` runs the same work inside ``apply``.

Bulkheads: ``apply`` is total.  A failure belongs to the input, timer or unit
that caused it: each input is applied on its own, each timer run on its own,
and one unit's numbers that break the vectorised step drop that unit alone
(the batch is re-run one unit at a time).  What failed is rejected (a
``rejected`` event on its key, rate-limited like every rejection), its goal is
dropped, and a ``Fault`` for the log comes out at most once a minute per key;
every other input and every other unit's direction in the tick goes out.  What
the planner cannot plan is refused before that, as a value: a goal whose step
would need more than ``max_iter`` steps (``constraints.reach_problem``), and a
goal closer to its unit than ``LENGTH_MIN_M`` or the tolerance has arrived.

Units are fresh only while they report: a unit the world learns of from a
goal, a restored mission or a peer's, and that has not reported, is stale
from the start and forgotten ``unit_forget_s`` later unless it reports.

Timers (threat expiry, unit silence, token debounce, forgetting, push
re-sends) sit in one heap, so a tick costs O(what is due), never a scan of
every unit.  Under ``cluster`` each unit is guided by the one live planner
rendezvous hashing gives it (``owns``); the others keep its mission.
"""

from __future__ import annotations

import contextlib
import copy
import heapq
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import msgspec
import numpy as np

from pfp_service.constraints import LENGTH_MIN_M, reach_problem
from pfp_service.core import Resolved, Stepper, StepStatus, Threat, ThreatField, resolve
from pfp_service.core.cull import MIN_THREATS, CullIndex, corridors_meet, influence_boxes
from pfp_service.core.params import FieldStats, field_stats
from pfp_service.core.plan import predict_many
from pfp_service.core.stepper import Advice, advise_many
from pfp_service.errors import FINITE_LIMIT, InputError
from pfp_service.service.events import (
    Deliberated,
    Fault,
    GoalCancelled,
    GoalSet,
    Input,
    InputRejected,
    Job,
    MissionRecord,
    MissionRestored,
    MissionShared,
    Outputs,
    PeerPlanner,
    StateReported,
    ThreatPut,
    ThreatRemoved,
    Tick,
    TokenChanged,
    UnitView,
    WorldSettings,
    mission_message,
    mission_of,
    rendezvous_weight,
    unit_key,
    where,
)
from pfp_service.wire import (
    ArrivedEvent,
    ConflictEvent,
    Direction,
    DirectionStatus,
    ForgottenEvent,
    Goal,
    Mission,
    RejectedEvent,
    ReplanEvent,
    StaleEvent,
    ThreatChange,
    ThreatSummary,
    ThreatUpdate,
    TrappedEvent,
    UnitKind,
    UnitState,
    UnitSummary,
    WorldSnapshot,
    keys,
)
from pfp_service.wire.geodetic import with_geodetic_many
from pfp_service.wire.messages import MAX_EVENT_ITEMS, MAX_SNAPSHOT_ITEMS

__all__ = [
    "Deliberated",
    "Fault",
    "GoalCancelled",
    "GoalSet",
    "Input",
    "InputRejected",
    "Job",
    "MissionRecord",
    "MissionRestored",
    "MissionShared",
    "Outputs",
    "PeerPlanner",
    "StateReported",
    "ThreatPut",
    "ThreatRemoved",
    "Tick",
    "TokenChanged",
    "UnitView",
    "World",
    "WorldSettings",
    "mission_message",
    "unit_key",
]

_STATUS = {
    StepStatus.EN_ROUTE: DirectionStatus.EN_ROUTE,
    StepStatus.ESCAPING: DirectionStatus.ESCAPING,
    StepStatus.ARRIVED: DirectionStatus.ARRIVED,
    StepStatus.TRAPPED: DirectionStatus.TRAPPED,
    # mission bounds are enforced on decode; a stepper verdict of these is a dead end all the same
    StepStatus.OUT_OF_BOUNDS: DirectionStatus.TRAPPED,
    StepStatus.INVALID: DirectionStatus.TRAPPED,
}
REJECTS_PER_S = 5  # rejected events per second per kind of key; the rest are counted in the next
FAULT_LOG_S = 60.0  # a fault is logged once per key in this long; the rest are counted in the next
FAULT_KEYS_MAX = 1024  # keys whose fault-log window is remembered; past it, one line for all the rest
_ANY_KEY = "*"  # the fault-log key of faults on keys past FAULT_KEYS_MAX


@dataclass(slots=True)
class _Unit:
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

    def token(self) -> tuple[int, int]:
        return (self.epoch, self.stepper.version if self.stepper is not None else -1)


@dataclass(slots=True)
class _Threat:
    update: ThreatUpdate
    threat: Threat
    expires_at: float | None


class World:
    """Units, goals and threats of one mission, and the steppers that guide the units."""

    def __init__(self, settings: WorldSettings | None = None) -> None:
        self.settings = settings or WorldSettings()
        self._units: dict[str, _Unit] = {}
        self._threats: dict[str, _Threat] = {}
        self._field: ThreatField | None = None
        self._cull: CullIndex | None = None
        self._stats: FieldStats | None = None
        self._touched: list[Threat] = []
        self._timers: list[tuple[float, int, str, str]] = []  # (when, seq, kind, id)
        self._timer_seq = 0
        self._stale = 0
        self._deliberating = 0
        self.overload = 0  # inputs refused at a limit
        self.rejected = 0
        self.pushes = 0  # directions sent without a report asking
        self.pushes_resent = 0
        self._reject_window: dict[str, tuple[float, int, int]] = {}  # kind -> (window start, sent, held)
        self._peers: set[str] = set()
        self._peers_gone: dict[str, float] = {}  # peer -> when its token went, until the debounce ends
        self.faults = 0  # inputs, timers and unit steps that failed inside the world (bulkheads)
        self._fault_log: dict[str, tuple[float, int]] = {}  # key -> (when last logged, held since)

    # -- queries (read-only) ------------------------------------------------------
    @property
    def field(self) -> ThreatField:
        if self._field is None:
            ordered = [self._threats[k].threat for k in sorted(self._threats)]
            self._field = ThreatField(ordered, self.settings.planner.intensity)
            self._cull = CullIndex(self._field.packed) if len(ordered) >= MIN_THREATS else None
            self._stats = field_stats(ordered)
        return self._field

    def counts(self) -> dict[str, int]:
        """O(1) figures for the status reply."""
        return {
            "units": len(self._units),
            "units_stale": self._stale,
            "threats": len(self._threats),
            "deliberating": self._deliberating,
            "overload": self.overload,
            "rejected": self.rejected,
            "units_owned": sum(1 for r in self._units.values() if r.owned),
            "pushes": self.pushes,
            "pushes_resent": self.pushes_resent,
            "faults": self.faults,
        }

    def view(self, unit_id: str) -> UnitView:
        """A detached copy of one unit and the threats in force (a preview runs on it, off the loop)."""
        rec = self._units.get(unit_id)
        threats = self.field.threats  # the same tuple while the field stands: a desk can cache it
        if rec is None:
            return UnitView(unit_id, None, None, None, None, threats, self.settings)
        stepper = copy.deepcopy(rec.stepper) if rec.stepper is not None else None
        return UnitView(
            unit_id, rec.position, rec.goal, rec.origin, stepper, threats, self.settings, rec.last_vector
        )

    def snapshot(
        self,
        now: float,
        limit: int = MAX_SNAPSHOT_ITEMS,
        units_from: str | None = None,
        threats_from: str | None = None,
        max_bytes: int | None = None,
        threats_limit: int | None = None,
    ) -> WorldSnapshot:
        """One page of what the planner holds, for the world queryable: threats, then units, sorted by id.

        Args:
            now: the clock, for TTLs left and time since last seen.
            limit: at most this many units, and this many threats unless
                ``threats_limit`` says otherwise.
            units_from, threats_from: the first ids listed (a former page's
                ``next_unit`` and ``next_threat``); ``None``: from the first.
            max_bytes: the page's items stop short of this much JSON
                (default ``SNAPSHOT_PAGE_BYTES``, so a reply always decodes).

        Returns:
            The page; its ``next_unit`` and ``next_threat`` say where the next
            one starts (``None``: that list is complete, or was not asked for
            with a limit of 0).  A page with room for nothing still lists one
            item, so paging always ends.
        """
        import bisect

        from pfp_service.wire.messages import SNAPSHOT_PAGE_BYTES

        room = SNAPSHOT_PAGE_BYTES if max_bytes is None else max_bytes

        def fits(item: msgspec.Struct) -> bool:
            nonlocal room
            size = len(msgspec.json.encode(item)) + 1  # and its comma
            if size > room and (units or threats):
                return False
            room -= size
            return True

        units: list[UnitSummary] = []
        threats: list[ThreatSummary] = []
        tids = sorted(self._threats)
        i = bisect.bisect_left(tids, threats_from) if threats_from is not None else 0
        tlimit = limit if threats_limit is None else threats_limit
        while i < len(tids) and len(threats) < tlimit:
            t = self._threats[tids[i]]
            ttl = None if t.expires_at is None else max(t.expires_at - now, 0.0)
            summary = ThreatSummary(id=tids[i], threat=t.update, ttl_s=ttl)
            if not fits(summary):
                break
            threats.append(summary)
            i += 1
        next_threat = tids[i] if i < len(tids) and tlimit else None
        uids = sorted(self._units)
        j = bisect.bisect_left(uids, units_from) if units_from is not None else 0
        while j < len(uids) and len(units) < limit:
            r = self._units[uids[j]]
            unit = UnitSummary(
                id=uids[j],
                kind=UnitKind(r.kind) if r.kind is not None else None,
                status=r.last_status,
                position=r.position,
                goal=r.goal.position if r.goal is not None else None,
                last_seen_s=max(now - r.last_seen, 0.0) if math.isfinite(r.last_seen) else None,
                distance_to_goal=r.last_distance,
                stale=r.stale,
                deliberating=r.job is not None,
                reason=r.last_reason[:1024],
                mission=mission_of(r.shared, self.settings.planner_id if r.owned else None),
            )
            if not fits(unit):
                break
            units.append(unit)
            j += 1
        return WorldSnapshot(
            planner=self.settings.planner_id,
            mission=self.settings.mission,
            units=units,
            threats=threats,
            units_total=len(self._units),
            threats_total=len(self._threats),
            next_unit=uids[j] if j < len(uids) and limit else None,
            next_threat=next_threat,
        )

    # -- the one way in -----------------------------------------------------------
    def apply(self, inputs: list[Input] | tuple[Input, ...], now: float) -> Outputs:
        """Apply a batch of inputs at ``now``; return what must go out."""
        out = Outputs()
        dirty: set[str] = set()
        changes: list[ThreatChange] = []
        self._touched = []  # threats put, moved or gone in this batch (old and new)
        for inp in inputs:
            try:
                self._apply_one(inp, now, dirty, changes, out)
            except Exception as exc:  # the bulkhead: this input alone fails
                key, unit = self._blame(inp)
                self._fault(key, exc, now, out, unit, dirty)
        if changes:
            dirty |= self._world_changed(now, out)
        first = len(out.directions)  # before: pushes sent again by the timers
        self._directions(dirty, now, out)
        self._pushes(out.directions[first:], now)
        if changes:
            guided = sorted(d.unit for d in out.directions if d.status is not DirectionStatus.NO_GOAL)
            shown = changes[:MAX_EVENT_ITEMS]
            reason = "; ".join(f"threat {c.threat} {c.change}" for c in shown[:4])
            if len(changes) > 4:
                reason += f"; and {len(changes) - 4} more"
            out.events.append(
                ReplanEvent(
                    planner=self.settings.planner_id,
                    units=guided[:MAX_EVENT_ITEMS],
                    reason=reason,
                    changes=shown,
                    more=len(changes) - len(shown),
                    more_units=max(len(guided) - MAX_EVENT_ITEMS, 0),
                )
            )
        return out

    def _apply_one(
        self, inp: Input, now: float, dirty: set[str], changes: list[ThreatChange], out: Outputs
    ) -> None:
        match inp:
            case StateReported(unit, state):
                self._state(unit, state, now, dirty, out)
            case GoalSet(unit, goal):
                self._goal(unit, goal, now, dirty, out)
            case GoalCancelled(unit):
                self._cancel(unit, dirty)
            case ThreatPut(tid, update):
                self._threat_put(tid, update, now, changes, out)
            case ThreatRemoved(tid):
                gone = self._threats.pop(tid, None)
                if gone is not None:
                    self._touched.append(gone.threat)
                    changes.append(ThreatChange(threat=tid, change="removed", position=gone.update.position))
            case TokenChanged(unit, alive):
                self._token(unit, alive, now)
            case InputRejected(key, error):
                self._reject(key, error, now, out)
            case Deliberated():
                self._deliberated(inp, now, dirty, out)
            case MissionRestored():
                self._restore(inp, now, out)
            case MissionShared(unit, mission):
                self._shared(unit, mission, now, out)
            case PeerPlanner(planner, alive):
                self._peer(planner, alive, now, dirty, out)
            case Tick(t):
                self._run_timers(t, changes, out, dirty)

    # -- bulkheads ------------------------------------------------------------------
    def _key(self, kind: keys.KeyKind, ident: str) -> str:
        """The key an input came on, spelled from the layout even for an id ``keys`` would refuse."""
        return keys.TEMPLATES[kind].format(mission=self.settings.mission, id=ident)

    def _blame(self, inp: Input) -> tuple[str, str | None]:
        """The key a failed input is rejected on, and the unit whose goal goes with it (if any)."""
        k = keys.KeyKind
        match inp:
            case StateReported(unit):
                return self._key(k.UNIT_STATE, unit), unit
            case GoalSet(unit) | GoalCancelled(unit) | MissionRestored(unit) | Deliberated(unit):
                return self._key(k.UNIT_GOAL, unit), unit
            case MissionShared(unit):
                return self._key(k.UNIT_MISSION, unit), unit
            case ThreatPut(tid) | ThreatRemoved(tid):
                return self._key(k.THREAT, tid), None
            case TokenChanged(unit):
                return self._key(k.ALIVE_UNIT, unit), None
            case PeerPlanner(planner):
                return self._key(k.ALIVE_PLANNER, planner), None
            case InputRejected(key):
                return key, None
        return self._key(k.EVENT, "tick"), None

    def _fault(
        self,
        key: str,
        exc: BaseException,
        now: float,
        out: Outputs,
        unit: str | None = None,
        dirty: set[str] | None = None,
        error: tuple[str, str, str] | None = None,
    ) -> None:
        """Something failed inside the world on ``key``'s account: drop it, reject it, log it once a minute.

        The unit named loses its goal (a goal it cannot be guided to is
        refused, not retried at every report) and gets ``no_goal``.
        """
        self.faults += 1
        rec = self._units.get(unit) if unit is not None else None
        said = ""
        if rec is not None:
            try:
                had = rec.goal is not None
                self._drop_mission(rec)
                said = "; the unit's goal was dropped" if had else ""
                if dirty is not None and rec.position is not None and not rec.stale:
                    dirty.add(rec.id)
            except Exception:  # a record too broken to reset: forget it (a report makes it afresh)
                self._units.pop(rec.id, None)
                if rec.stale:
                    self._stale -= 1
        name, detail, at = error if error is not None else (type(exc).__name__, str(exc)[:200], where(exc))
        reason = f"not applied: {name} inside the planner ({detail}); this input alone was dropped{said}"
        self._reject(key, InputError("$", reason), now, out)
        # the operator's log: once a minute per key, and never a traceback
        if key not in self._fault_log and len(self._fault_log) >= FAULT_KEYS_MAX:
            for old, (when, _held) in list(self._fault_log.items()):
                if now - when >= FAULT_LOG_S:
                    del self._fault_log[old]
            if len(self._fault_log) >= FAULT_KEYS_MAX:
                key = _ANY_KEY
        when, held = self._fault_log.get(key, (-math.inf, 0))
        if now - when < FAULT_LOG_S:
            self._fault_log[key] = (when, held + 1)
            return
        self._fault_log[key] = (now, 0)
        out.faults.append(Fault(key, name, detail, at, held))

    # -- inputs ---------------------------------------------------------------------
    def _unit(
        self,
        unit_id: str,
        now: float,
        out: Outputs,
        key: Callable[[str, str], str],
        reported: bool = False,
    ) -> _Unit | None:
        """The unit's record, made at its first input; ``key`` names the input's key for a refusal.

        A record made by anything but a report (a goal, a restored or a
        peer's mission) is stale from the start: it has not been heard from,
        and it is forgotten ``unit_forget_s`` later unless it reports.
        """
        rec = self._units.get(unit_id)
        if rec is None:
            if len(self._units) >= self.settings.max_units:
                self.overload += 1
                err = InputError("$", f"planner at max_units ({self.settings.max_units})")
                self._reject(key(self.settings.mission, unit_id), err, now, out)
                return None
            rec = self._units[unit_id] = _Unit(unit_id, unit_key(unit_id))
            rec.owned = self.owns(unit_id)
            if not reported:
                rec.stale = True
                rec.stale_since = now
                self._stale += 1
                if self.settings.unit_forget_s is not None:
                    self._timer(now + self.settings.unit_forget_s, "forget", unit_id)
        return rec

    def _state(self, unit_id: str, msg: UnitState, now: float, dirty: set[str], out: Outputs) -> None:
        rec = self._unit(unit_id, now, out, keys.unit_state, reported=True)
        if rec is None:
            return
        rec.position = (msg.position[0], msg.position[1])
        rec.seq = msg.seq
        rec.kind = msg.kind.value if msg.kind is not None else rec.kind
        rec.last_seen = now
        if rec.stale:
            rec.stale = False
            rec.stale_since = None
            self._stale -= 1
        rec.token_gone_since = None  # a report is proof of life, whatever the token says
        rec.push = None  # it is answered now
        if not rec.silence_timer:
            rec.silence_timer = True
            self._timer(now + self.settings.unit_stale_s, "silence", unit_id)
        if not rec.owned:  # another planner guides it; its report keeps it fresh here too
            return
        if rec.goal is not None and rec.stepper is None:
            self._start(rec, now, out)
        dirty.add(unit_id)

    def _goal(self, unit_id: str, goal: Goal, now: float, dirty: set[str], out: Outputs) -> None:
        rec = self._unit(unit_id, now, out, keys.unit_goal)
        if rec is None:
            return
        # a peer's mission for this very goal may have come first: keep it for a takeover
        keep = rec.shared if not rec.owned and rec.shared is not None and rec.shared[0] == goal else None
        self._drop_mission(rec)
        rec.goal = goal
        rec.shared = keep
        if rec.position is not None and rec.owned:
            self._start(rec, now, out)
            if not rec.stale:
                dirty.add(unit_id)

    def _restore(self, m: MissionRestored, now: float, out: Outputs) -> None:
        rec = self._unit(m.unit, now, out, keys.unit_goal)
        if rec is None:
            return
        self._drop_mission(rec)
        rec.goal = m.goal
        rec.shared = (m.goal, m.origin, m.params)
        if rec.owned:
            self._start(rec, now, out, record=False)

    def _peer(self, planner: str, alive: bool, now: float, dirty: set[str], out: Outputs) -> None:
        if planner == self.settings.planner_id:
            return
        if not alive:  # acted on only if still gone after the debounce (a router restart flaps every token)
            if planner in self._peers and planner not in self._peers_gone:
                self._peers_gone[planner] = now
                self._timer(now + self.settings.liveliness_debounce_s, "peer", planner)
            return
        if self._peers_gone.pop(planner, None) is not None or planner in self._peers:
            return  # back within the debounce, or known: nothing moves
        self._peers.add(planner)
        if self.settings.cluster:
            self._rebalance(now, dirty, out)
        else:
            reason = (
                f"planner {planner!r} also serves mission {self.settings.mission!r}; both answer every unit"
            )
            out.events.append(ConflictEvent(planner=self.settings.planner_id, other=planner, reason=reason))

    # -- scale-out -------------------------------------------------------------------
    def owns(self, unit_id: str) -> bool:
        """Whether this planner guides ``unit_id``: rendezvous hashing of unit x planner, highest wins.

        Without ``cluster`` it owns every unit.  A planner joining takes about
        1/K of each planner's units; one leaving hands over only its own.
        """
        if not self.settings.cluster or not self._peers:
            return True
        me = self.settings.planner_id
        best = max((*self._peers, me), key=lambda p: (rendezvous_weight(unit_id, p), p))
        return best == me

    def _rebalance(self, now: float, dirty: set[str], out: Outputs) -> None:
        if not self.settings.cluster:
            return
        for rec in self._units.values():
            owned = self.owns(rec.id)
            if owned == rec.owned:
                continue
            rec.owned = owned
            if owned:  # taken over: guided from the mission its last owner fixed, told at once
                if rec.goal is not None and rec.position is not None:
                    self._start(rec, now, out)
                if rec.position is not None and not rec.stale:
                    dirty.add(rec.id)
            else:  # handed over: the new owner guides it now
                self._supersede(rec)
                rec.stepper = None
                rec.push = None
                rec.last_status = None

    def _shared(self, unit_id: str, mission: Mission, now: float, out: Outputs) -> None:
        rec = self._unit(unit_id, now, out, keys.unit_mission)
        if rec is None or rec.owned:
            return  # our own missions come back to us too: ours stands
        params = Resolved(**msgspec.structs.asdict(mission.params))  # type: ignore[arg-type]
        rec.shared = (mission.goal, (mission.origin[0], mission.origin[1]), params)

    def _cancel(self, unit_id: str, dirty: set[str]) -> None:
        rec = self._units.get(unit_id)
        if rec is None or rec.goal is None:
            return
        self._drop_mission(rec)
        if rec.position is not None and not rec.stale:
            dirty.add(unit_id)

    def _drop_mission(self, rec: _Unit) -> None:
        rec.goal = None
        rec.stepper = None
        rec.origin = None
        rec.last_status = None
        rec.last_reason = ""
        rec.last_distance = None
        rec.last_vector = None
        rec.shared = None
        rec.epoch += 1
        self._supersede(rec)

    def _threat_put(
        self, tid: str, msg: ThreatUpdate, now: float, changes: list[ThreatChange], out: Outputs
    ) -> None:
        if tid not in self._threats and len(self._threats) >= self.settings.max_threats:
            self.overload += 1
            err = InputError("$", f"planner at max_threats ({self.settings.max_threats})")
            self._reject(keys.threat(self.settings.mission, tid), err, now, out)
            return
        ttl = msg.ttl_s if msg.ttl_s is not None else self.settings.threat_ttl_s
        expires = None if ttl is None else now + ttl
        old = self._threats.get(tid)
        if old is not None:
            self._touched.append(old.threat)
        self._threats[tid] = new = _Threat(msg, msg.to_threat(tid), expires)
        self._touched.append(new.threat)
        if expires is not None:
            self._timer(expires, "expire", tid)
        changes.append(ThreatChange(threat=tid, change="put", position=msg.position))

    def _token(self, unit_id: str, alive: bool, now: float) -> None:
        rec = self._units.get(unit_id)
        if rec is None:
            return  # a token alone makes no unit: only a report does
        if alive:
            rec.token_gone_since = None
        elif rec.token_gone_since is None:
            rec.token_gone_since = now
            self._timer(now + self.settings.liveliness_debounce_s, "token", unit_id)

    def _reject(self, key: str, err: InputError, now: float, out: Outputs) -> None:
        """Count every rejection; send at most ``REJECTS_PER_S`` events a second per kind of key."""
        self.rejected += 1
        try:
            kind = keys.parse(key).kind.value
        except InputError:
            kind = "unknown"
        start, sent, held = self._reject_window.get(kind, (now, 0, 0))
        if now - start >= 1.0:
            start, sent = now, 0
        if sent >= REJECTS_PER_S:
            self._reject_window[kind] = (start, sent, held + 1)
            return
        ev = RejectedEvent.of(key, err, planner=self.settings.planner_id)
        if held:
            ev = msgspec.structs.replace(ev, suppressed=held)
        out.events.append(ev)
        self._reject_window[kind] = (start, sent + 1, 0)

    def _deliberated(self, done: Deliberated, now: float, dirty: set[str], out: Outputs) -> None:
        rec = self._units.get(done.unit)
        if rec is None or rec.job is None or rec.job.token != done.token:
            return  # superseded: a newer goal or world is in force
        kind = rec.job.kind
        rec.job = None
        self._deliberating -= 1
        if rec.stepper is None or rec.token() != done.token:
            return
        if done.error is not None:  # it failed where it ran: this unit's goal goes, as a fault here would
            err = RuntimeError(done.error[1])
            self._fault(self._key(keys.KeyKind.UNIT_GOAL, rec.id), err, now, out, rec.id, dirty, done.error)
            return
        if done.stepper is None:  # ran past its deadline: descend meanwhile, and ask again
            if kind == "foresee":
                rec.stepper.look_ahead_again()  # at its next report, behind the queue
            else:
                rec.stepper.pending = None  # a trap is asked again by the trap watch itself
        elif rec.stepper.adopt(done.stepper) and rec.position is not None and not rec.stale:
            dirty.add(rec.id)  # a route or a verdict: told at once, not at its next report

    # -- timers ---------------------------------------------------------------------
    def _timer(self, when: float, kind: str, ident: str) -> None:
        self._timer_seq += 1
        heapq.heappush(self._timers, (when, self._timer_seq, kind, ident))

    def _run_timers(self, now: float, changes: list[ThreatChange], out: Outputs, dirty: set[str]) -> None:
        while self._timers and self._timers[0][0] <= now:
            _, _, kind, ident = heapq.heappop(self._timers)
            try:
                self._timer_due(kind, ident, now, changes, out, dirty)
            except Exception as exc:  # the bulkhead: this timer alone fails
                if kind == "expire":
                    self._fault(self._key(keys.KeyKind.THREAT, ident), exc, now, out)
                elif kind == "peer":
                    self._fault(self._key(keys.KeyKind.ALIVE_PLANNER, ident), exc, now, out)
                else:
                    self._fault(self._key(keys.KeyKind.UNIT_GOAL, ident), exc, now, out, ident, dirty)

    def _timer_due(
        self, kind: str, ident: str, now: float, changes: list[ThreatChange], out: Outputs, dirty: set[str]
    ) -> None:
        s = self.settings
        if kind == "peer":  # a peer planner's token gone for the whole debounce: its units move
            gone = self._peers_gone.get(ident)
            if gone is not None and now - gone >= s.liveliness_debounce_s:
                del self._peers_gone[ident]
                self._peers.discard(ident)
                self._rebalance(now, dirty, out)
            return
        if kind == "expire":
            t = self._threats.get(ident)
            if t is not None and t.expires_at is not None and t.expires_at <= now:
                del self._threats[ident]
                self._touched.append(t.threat)
                changes.append(ThreatChange(threat=ident, change="expired", position=t.update.position))
            return
        rec = self._units.get(ident)
        if rec is None:
            return
        if kind == "silence":
            if now - rec.last_seen <= s.unit_stale_s:  # heard since: look again when it could be due
                self._timer(max(rec.last_seen + s.unit_stale_s, now) + 1e-9, "silence", ident)
                return
            rec.silence_timer = False
            self._go_stale(rec, now, f"silent for {now - rec.last_seen:.3g} s", out)
        elif kind == "token":
            gone = rec.token_gone_since
            if gone is not None and now - gone >= s.liveliness_debounce_s:
                self._go_stale(rec, now, "liveliness token gone", out)
        elif kind == "push" and rec.push is not None and rec.push_tries > 0 and not rec.stale:
            rec.push_tries -= 1
            self.pushes_resent += 1
            out.directions.append(rec.push)
            if rec.push_tries:
                self._timer(now + s.push_retry_s, "push", ident)
        elif kind == "forget" and self._forgettable(rec, now):
            self._forget(rec, now, out)

    def _pushes(self, fresh: list[Direction], now: float) -> None:
        """Directions no report asked for (a world change, a route landing) are sent again until answered.

        Directions go out with congestion control DROP, so a burst may lose
        some; a pushed unit gets the same direction again every
        ``push_retry_s``, up to ``push_retries`` times, until its next report
        is answered.
        """
        for d in fresh:
            rec = self._units.get(d.unit)
            if rec is None or rec.last_seen >= now:  # answering a report of this batch
                continue
            if (rec.push is None or rec.push_tries == 0) and self.settings.push_retries > 0:
                self._timer(now + self.settings.push_retry_s, "push", rec.id)
            rec.push = d
            rec.push_tries = self.settings.push_retries
            self.pushes += 1

    def _forgettable(self, rec: _Unit, now: float) -> bool:
        limit = self.settings.unit_forget_s
        return (
            rec.stale and rec.stale_since is not None and limit is not None and now - rec.stale_since >= limit
        )

    def _go_stale(self, rec: _Unit, now: float, reason: str, out: Outputs) -> None:
        if rec.stale or rec.position is None:
            return
        rec.stale = True
        rec.stale_since = now
        self._stale += 1
        out.events.append(
            StaleEvent(planner=self.settings.planner_id, unit=rec.id, position=rec.position, reason=reason)
        )
        if self.settings.unit_forget_s is not None:
            self._timer(now + self.settings.unit_forget_s, "forget", rec.id)

    def _forget(self, rec: _Unit, now: float, out: Outputs) -> None:
        self._supersede(rec)
        del self._units[rec.id]
        self._stale -= 1
        stale_s = now - rec.stale_since if rec.stale_since is not None else 0.0
        out.events.append(ForgottenEvent(planner=self.settings.planner_id, unit=rec.id, stale_s=stale_s))

    # -- planning -------------------------------------------------------------------
    def _start(self, rec: _Unit, now: float, out: Outputs, record: bool = True) -> bool:
        """Fix the unit's mission (x0 and parameters) and give it a stepper.

        A mission restored or shared for this very goal is kept, so a restart or
        a takeover guides the unit exactly as before; otherwise x0 is where the
        unit is now.  A goal closer than ``LENGTH_MIN_M`` is planned with a
        step of that length, so it has arrived; a mission the planner cannot
        plan (``constraints.reach_problem``) is refused: the goal is rejected
        on its key, dropped, and ``False`` returned.
        """
        assert rec.goal is not None
        goal = (rec.goal.position[0], rec.goal.position[1])
        if rec.shared is not None and rec.shared[0] == rec.goal:
            origin, resolved = rec.shared[1], rec.shared[2]
        else:
            assert rec.position is not None
            origin = rec.position
            fld = self.field  # builds the stats with it
            params = self.settings.params_for(rec.goal)
            if math.dist(origin, goal) < LENGTH_MIN_M and (params.step or 0.0) < LENGTH_MIN_M:
                params = params.merged(step=LENGTH_MIN_M)  # closer than the planner resolves: arrived
            resolved = resolve(params, origin, goal, fld.threats, self._stats)
        problem = reach_problem(math.dist(origin, goal), resolved.step, resolved.max_iter, resolved.tolerance)
        if problem is not None:
            path = "$.step" if rec.goal.step is not None else "$.position"
            self._reject(self._key(keys.KeyKind.UNIT_GOAL, rec.id), InputError(path, problem), now, out)
            self._drop_mission(rec)
            return False
        rec.shared = (rec.goal, origin, resolved)
        rec.origin = origin
        rec.stepper = Stepper(origin, goal, resolved, self.settings.bounds, rec.key)
        rec.stepper.defer = self.settings.deliberation == "deferred"
        if record:
            out.missions.append(MissionRecord(rec.id, rec.epoch, origin, rec.goal, resolved))
        return True

    def _supersede(self, rec: _Unit) -> None:
        if rec.job is not None:
            rec.job.cancelled = True
            rec.job = None
            self._deliberating -= 1

    def _world_changed(self, now: float, out: Outputs) -> set[str]:
        """The threats changed: re-judge and re-direct the units the change can reach.

        A unit is reached when a touched threat's influence box (where it is
        not culled, ``cull.influence_boxes``) meets the unit's corridor to its
        goal (``cull.corridors_meet``), or when it is escaping or deliberating
        (its route or its job was judged under the old field).  Every other
        unit's direction is unchanged within the cull bound, and it is left
        alone: a contingency costs what it touches, not the whole fleet.  If
        the vectorised test fails, every guided unit counts as reached.
        """
        self._field = None
        guided = [r for r in self._units.values() if r.stepper is not None and r.position is not None]
        if not guided:
            return set()
        try:
            touched = ThreatField(self._touched, self.settings.planner.intensity)
            boxes = influence_boxes(touched.packed)
            starts = np.array([r.position for r in guided], dtype=float)
            ends = np.array([r.stepper.goal for r in guided], dtype=float)  # type: ignore[union-attr, type-var]
            reached = corridors_meet(starts, ends, boxes).tolist()
        except Exception:  # judged afresh, all of them: dearer, never wrong
            reached = [True] * len(guided)
        dirty: set[str] = set()
        for rec, hit in zip(guided, reached):
            try:
                assert rec.stepper is not None
                if not (
                    hit or rec.stepper.escaping or rec.job is not None or rec.stepper.pending is not None
                ):
                    continue
                rec.stepper.world_changed()
                self._supersede(rec)
            except Exception as exc:
                self._fault(self._key(keys.KeyKind.UNIT_GOAL, rec.id), exc, now, out, rec.id, dirty)
                continue
            if not rec.stale:
                dirty.add(rec.id)
        return dirty

    def _directions(self, unit_ids: set[str], now: float, out: Outputs) -> None:
        """A fresh direction for each unit named (stale and unknown units get none).

        Units with a goal are advised in one vectorised call, their look-ahead
        points in ``lookahead`` more; the rest get ``no_goal``.  If a unit's
        numbers break the batch, it is run again one unit at a time and the
        units that fail alone are dropped (``_fault``); a direction that is
        not finite drops its unit the same way.
        """
        guided: list[_Unit] = []
        for uid in sorted(unit_ids):
            rec = self._units.get(uid)
            if rec is None or rec.stale or rec.position is None or not rec.owned:
                continue
            if rec.stepper is None:
                out.directions.append(self._no_goal(rec))
            else:
                guided.append(rec)
        if not guided:
            return
        fld = self.field
        dropped: list[_Unit] = []  # units whose step failed: told no_goal once the rest are out
        try:
            advices = self._advise(guided, fld)
        except Exception:  # one unit's numbers broke the batch: each alone, the poisoned dropped
            advices, alone = [], guided
            guided = []
            for rec in alone:
                try:
                    advices += self._advise([rec], fld)
                    guided.append(rec)
                except Exception as exc:
                    self._unit_fault(rec, exc, now, out, dropped)
        if not all(map(_finite_advice, advices)):
            for rec, adv in zip(guided, advices):
                if not _finite_advice(adv):
                    err = FloatingPointError(f"a direction that is not finite at {rec.position}")
                    self._unit_fault(rec, err, now, out, dropped)
            kept = [(r, a) for r, a in zip(guided, advices) if _finite_advice(a)]
            guided, advices = [r for r, _ in kept], [a for _, a in kept]
        try:
            ahead = self._lookahead(guided, advices, fld)
        except Exception:
            ahead, pairs = [], list(zip(guided, advices))
            guided, advices = [], []
            for rec, adv in pairs:
                try:
                    ahead += self._lookahead([rec], [adv], fld)
                    guided.append(rec)
                    advices.append(adv)
                except Exception as exc:
                    self._unit_fault(rec, exc, now, out, dropped)
        first = len(out.directions)
        sent: list[_Unit] = []
        for rec, adv, points in zip(guided, advices, ahead):
            try:
                d = self._direction(rec, adv, _within_map(points), out)
                if rec.stepper is not None and rec.stepper.pending is not None and rec.job is None:
                    self._ask(rec, fld, now, out)
            except Exception as exc:
                self._unit_fault(rec, exc, now, out, dropped)
                continue
            out.directions.append(d)
            sent.append(rec)
        if self.settings.origin is not None and sent:  # lat/lon for the whole tick in one conversion
            self._geodetic(out, first, [r.position for r in sent])
        for rec in dropped:
            if rec.id in self._units and rec.position is not None and not rec.stale and rec.owned:
                out.directions.append(self._no_goal(rec))

    def _advise(self, guided: list[_Unit], fld: ThreatField) -> list[Advice]:
        steppers: list[Stepper] = [r.stepper for r in guided]  # type: ignore[misc]
        return advise_many(steppers, fld, np.array([r.position for r in guided], dtype=float), self._cull)

    def _unit_fault(
        self, rec: _Unit, exc: BaseException, now: float, out: Outputs, dropped: list[_Unit]
    ) -> None:
        """One unit's step failed: its goal is dropped and rejected, and it is to be told ``no_goal``."""
        self._fault(self._key(keys.KeyKind.UNIT_GOAL, rec.id), exc, now, out, rec.id)
        dropped.append(rec)

    def _no_goal(self, rec: _Unit) -> Direction:
        rec.last_status = DirectionStatus.NO_GOAL
        return Direction(
            unit=rec.id,
            seq=rec.seq,
            status=DirectionStatus.NO_GOAL,
            vector=(0.0, 0.0),
            planner=self.settings.planner_id,
        )

    def _geodetic(self, out: Outputs, first: int, positions: list[tuple[float, float] | None]) -> None:
        """Lat/lon and true bearing for the directions from ``first`` on; one that fails goes without."""
        fresh = out.directions[first:]
        try:
            converted = with_geodetic_many(fresh, self.settings.origin, positions)
        except Exception:
            converted = list(fresh)
            for i, (d, p) in enumerate(zip(fresh, positions)):
                with contextlib.suppress(Exception):  # this one goes in metres only
                    (converted[i],) = with_geodetic_many([d], self.settings.origin, [p])
        # a point thousands of km off the origin has no meaningful lat/lon: that one goes in metres only
        out.directions[first:] = [g if _geo_ok(g) else d for d, g in zip(fresh, converted)]

    def _ask(self, rec: _Unit, fld: ThreatField, now: float, out: Outputs) -> None:
        assert rec.stepper is not None and rec.stepper.pending is not None
        work = copy.deepcopy(rec.stepper)
        kind = rec.stepper.pending.kind
        deadline = now + self.settings.deliberation_budget_s
        rec.job = Job(rec.id, rec.token(), kind, work, fld, deadline)
        self._deliberating += 1
        out.jobs.append(rec.job)

    def _lookahead(
        self, guided: list[_Unit], advices: list[Advice], fld: ThreatField
    ) -> list[list[tuple[float, float]]]:
        n = self.settings.lookahead
        result: list[list[tuple[float, float]]] = [[] for _ in guided]
        if n <= 0:
            return result
        idx = [i for i, a in enumerate(advices) if not a.status.terminal]
        if not idx:
            return result
        steppers = []
        starts = []
        for i in idx:
            rec, adv = guided[i], advices[i]
            assert rec.stepper is not None and rec.position is not None
            steppers.append(rec.stepper)
            starts.append(adv.to)  # where the step advised ends (steprule.judge)
        tracks = predict_many(steppers, fld, np.array(starts), n - 1, self._cull)
        for i, track in zip(idx, tracks):
            result[i] = track
        return result

    def _direction(
        self, rec: _Unit, adv: Advice, points: list[tuple[float, float]], out: Outputs
    ) -> Direction:
        assert rec.position is not None
        status = _STATUS[adv.status]
        if status is not rec.last_status:
            self._transition(rec, status, adv, out)
        rec.last_status = status
        rec.last_reason = adv.reason
        rec.last_distance = min(adv.distance, FINITE_LIMIT)  # the wire's bound: a diagonal of the map is more
        rec.last_vector = None if adv.status.terminal else (adv.dx, adv.dy)
        heading = None
        if not adv.status.terminal and (adv.dx or adv.dy):
            heading = math.degrees(math.atan2(adv.dx, adv.dy)) % 360.0
            heading = 0.0 if heading >= 360.0 else heading  # -1e-300 % 360 is 360.0
        d = Direction(
            unit=rec.id,
            seq=rec.seq,
            status=status,
            vector=(adv.dx, adv.dy),
            heading_deg=heading,
            distance_to_goal=rec.last_distance,
            threat_level=min(max(adv.level, 0.0), FINITE_LIMIT),  # the wire's bound, even for absurd weights
            lookahead=points,
            reason=adv.reason[:1024],
            deliberating=adv.deliberating or rec.job is not None,
            planner=self.settings.planner_id,
        )
        return d

    def _transition(self, rec: _Unit, status: DirectionStatus, adv: Advice, out: Outputs) -> None:
        assert rec.position is not None
        p = self.settings.planner_id
        if status is DirectionStatus.ARRIVED:
            out.events.append(
                ArrivedEvent(planner=p, unit=rec.id, position=rec.position, distance_to_goal=adv.distance)
            )
        elif status is DirectionStatus.TRAPPED:
            out.events.append(
                TrappedEvent(planner=p, unit=rec.id, position=rec.position, reason=adv.reason[:1024])
            )


def _finite_advice(a: Advice) -> bool:
    return math.isfinite(a.dx + a.dy + a.level + a.distance)


def _within_map(track: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The look-ahead up to its first point off the wire's map (±``FINITE_LIMIT``, or not a number)."""
    lim = FINITE_LIMIT
    if all(-lim <= c <= lim for c in itertools.chain.from_iterable(track)):
        return track
    for i, (x, y) in enumerate(track):
        if not (-lim <= x <= lim and -lim <= y <= lim):
            return track[:i]
    return track


def _geo_ok(d: Direction) -> bool:
    """Whether the lat/lon a direction was given are within the wire's bounds."""
    b = d.true_bearing_deg
    return (b is None or -360.0 <= b <= 360.0) and all(
        -90.0 <= g.lat <= 90.0 and -180.0 <= g.lon <= 180.0 for g in d.lookahead_geo
    )
