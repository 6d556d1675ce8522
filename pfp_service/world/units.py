"""A unit's record and its one owner: the unit's phase, the steps that move it, and every write that decides it.

A unit is in one phase (``Phase``: unknown, stale, a peer's, no goal,
guided, deliberating, arrived, trapped), derived from the fields that
decide it (``phase_of``).  ``TRANSITIONS`` lists, for each step that can
happen to a unit (``Step``), the phases it may leave and the phases it may
reach from each.  ``Units`` is the only writer of a unit's phase and of the
fields that decide it -- owned, position, stale, goal, mission and stepper,
job, last verdict -- and of the core state the world changes in a stepper:
the world's other parts decide (``liveness`` when a unit is stale,
``steering`` what a direction says, ``missions`` what mission a goal
fixes) and hand their verdict or value here.  A step the table does not
allow raises ``PhaseError``: a defect, which the world's bulkhead turns into
that unit's fault (its goal dropped), and which fails a test loudly.

Liveness keeps its own bookkeeping on the record (``silence_timer``,
``token_gone_since``, ``push``, ``push_tries``, ``progress``): none decides
the phase.  Pure values: ``now`` is a parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import NamedTuple

import msgspec

from pfp_service.core import Resolved, Stepper
from pfp_service.wire import Direction, DirectionStatus, Goal, GoalMobility, Mission, UnitPhase
from pfp_service.world.events import Deliberated, Job, unit_key
from pfp_service.world.mobility import sight_height, slope_limit
from pfp_service.world.progress import ProgressWatch

__all__ = [
    "TRANSITIONS",
    "Answer",
    "Phase",
    "PhaseError",
    "Started",
    "Step",
    "UnitRecord",
    "Units",
    "Verdict",
    "phase_of",
]

Phase = UnitPhase  # the phase is on the wire too (``UnitSummary.phase``): one enum


class Step(StrEnum):
    """What can happen to a unit: each is one method of ``Units``."""

    MADE = "made"  # its record made, by a report or anything else (``add``)
    REPORTED = "reported"  # a report
    WENT_STALE = "went_stale"  # silent, or its token gone for the debounce
    FORGOTTEN = "forgotten"  # stale for ``unit_forget_s``: its record goes
    GOAL_SET = "goal_set"  # a goal set or a mission restored: a new epoch
    GOAL_DROPPED = "goal_dropped"  # cancelled, refused, or failed inside the planner
    STARTED = "started"  # its mission fixed and a stepper given
    STEERED = "steered"  # a direction's verdict recorded (en route, escaping, arrived, trapped, no goal)
    ASKED = "asked"  # a deliberation job asked
    ANSWERED = "answered"  # its job came back
    WORLD_CHANGED = "world_changed"  # the threats or zones changed within its reach: judged afresh
    HANDED_OVER = "handed_over"  # another planner of the cluster guides it now
    TAKEN_OVER = "taken_over"  # this planner guides it again


class PhaseError(RuntimeError):
    """A step the unit's phase does not allow (``TRANSITIONS``): a defect in the world, never bad input."""


P = Phase
_FRESH = frozenset({P.NO_GOAL, P.GUIDED, P.DELIBERATING, P.ARRIVED, P.TRAPPED})
_JUDGED = frozenset({P.GUIDED, P.ARRIVED, P.TRAPPED})  # guided, and no job: what its last verdict says
GONE: frozenset[Phase] = frozenset()  # the record goes: no phase after


def _same(*phases: Phase) -> dict[Phase, frozenset[Phase]]:
    return {p: frozenset({p}) for p in phases}


# (phase, step) -> the phases the step may leave the unit in; a pair not listed is refused
TRANSITIONS: dict[tuple[Phase, Step], frozenset[Phase]] = {
    (P.UNKNOWN, Step.MADE): frozenset({P.UNKNOWN, P.PEER}),
    # a report of a fresh unit changes nothing that decides its phase, and is not looked up here
    (P.PEER, Step.REPORTED): frozenset({P.PEER}),
    (P.UNKNOWN, Step.REPORTED): frozenset({P.NO_GOAL, P.GUIDED}),
    (P.STALE, Step.REPORTED): _FRESH,  # as it was: its verdict and its job are kept while it is silent
    **{(p, Step.WENT_STALE): frozenset({P.STALE}) for p in _FRESH},
    (P.PEER, Step.WENT_STALE): frozenset({P.PEER}),
    **{(p, Step.FORGOTTEN): GONE for p in (P.UNKNOWN, P.STALE, P.PEER)},
    **{(p, Step.GOAL_SET): to for p, to in _same(P.UNKNOWN, P.STALE, P.PEER).items()},
    **{(p, Step.GOAL_SET): frozenset({P.GUIDED}) for p in _FRESH},
    **{(p, Step.GOAL_DROPPED): to for p, to in _same(P.UNKNOWN, P.STALE, P.PEER).items()},
    **{(p, Step.GOAL_DROPPED): frozenset({P.NO_GOAL}) for p in _FRESH - {P.NO_GOAL}},
    **{(p, Step.STARTED): to for p, to in _same(P.UNKNOWN, P.STALE, P.GUIDED).items()},
    **{(p, Step.STEERED): _JUDGED for p in _JUDGED},  # an arrived unit driven off its goal is guided again
    **{(p, Step.STEERED): to for p, to in _same(P.DELIBERATING, P.NO_GOAL).items()},
    (P.GUIDED, Step.ASKED): frozenset({P.DELIBERATING}),  # its verdict is kept before it is asked
    (P.DELIBERATING, Step.ANSWERED): _JUDGED,
    (P.STALE, Step.ANSWERED): frozenset({P.STALE}),
    **{(p, Step.WORLD_CHANGED): to for p, to in _same(P.STALE, *_JUDGED).items()},
    (P.DELIBERATING, Step.WORLD_CHANGED): _JUDGED,  # its job superseded
    **{(p, Step.HANDED_OVER): frozenset({P.PEER}) for p in Phase if p is not P.PEER},
    (P.PEER, Step.TAKEN_OVER): frozenset({P.UNKNOWN, P.STALE, P.NO_GOAL, P.GUIDED}),
}


@dataclass(slots=True)
class UnitRecord:
    id: str
    key: int
    position: tuple[float, float] | None = None
    seq: int | None = None
    kind: str | None = None
    mobility: GoalMobility | None = None  # the class its states name (``world.mobility``): kept till another
    last_seen: float = -math.inf
    goal: Goal | None = None
    goal_gone: str = ""  # why it has none since one was dropped: its ``no_goal`` directions' reason
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
    phase: Phase = Phase.UNKNOWN  # written by ``Units`` only

    def token(self) -> tuple[int, int]:
        """What a deliberation result must match to be adopted: the goal's epoch and the world's version."""
        return (self.epoch, self.stepper.version if self.stepper is not None else -1)

    def live(self) -> bool:
        """Whether the unit is told directions: it has reported, is not stale, and this planner guides it."""
        return self.position is not None and not self.stale and self.owned


def phase_of(rec: UnitRecord) -> Phase:
    """The phase the fields of ``rec`` say it is in (``Units`` records it at every step)."""
    if not rec.owned:
        return P.PEER
    if rec.position is None:
        return P.UNKNOWN
    if rec.stale:
        return P.STALE
    if rec.goal is None:
        return P.NO_GOAL
    if rec.job is not None:
        return P.DELIBERATING
    status = rec.last_status
    if status is DirectionStatus.ARRIVED:
        return P.ARRIVED
    if status is DirectionStatus.TRAPPED:
        return P.TRAPPED
    return P.GUIDED


class Verdict(NamedTuple):
    """What a direction says of a unit, to keep on its record (``steering.direction``)."""

    status: DirectionStatus
    reason: str
    distance: float | None
    vector: tuple[float, float] | None


NO_GOAL = Verdict(DirectionStatus.NO_GOAL, "", None, None)


class Started(NamedTuple):
    """A mission fixed for a unit's goal (``missions.start``): kept on its record by ``Units.started``."""

    shared: tuple[Goal, tuple[float, float], Resolved]
    stepper: Stepper


class Answer(StrEnum):
    """What a job that came back means for the world (``Units.deliberated``)."""

    IGNORED = "ignored"  # not the unit's job, or for a goal or world no longer in force
    QUIET = "quiet"  # adopted (or asked again later): the unit's next report is answered as ever
    TELL = "tell"  # a route or a verdict: the unit is told at once
    FAILED = "failed"  # it failed where it ran: the unit's goal goes


class Units:
    """Every unit's record, the counts kept as they change, and the one writer of what decides a phase."""

    def __init__(self) -> None:
        self.records: dict[str, UnitRecord] = {}
        self.stale = 0  # units stale
        self.deliberating = 0  # units with a job asked and not answered
        self.superseded: list[Job] = []  # jobs asked and no longer wanted, until the world says so
        # bumped by every write of a unit's position, staleness or goal and by a record made or dropped:
        # a reader's cache of where the units are (dispersion's neighbour index) stands while it does
        self.version = 0

    def seen(self) -> int:
        """``version``, for a cache to key on (a bound method: a copied world's caches read their own book)."""
        return self.version

    def _to(self, rec: UnitRecord, step: Step, gone: bool = False) -> None:
        """Record the phase ``step`` left ``rec`` in (``gone``: its record goes), if ``TRANSITIONS`` allows it."""
        new = None if gone else phase_of(rec)
        allowed = TRANSITIONS.get((rec.phase, step))
        if allowed is None or (new not in allowed if new is not None else allowed != GONE):
            to = "gone" if new is None else new.value
            raise PhaseError(f"unit {rec.id!r}: {step.value} from {rec.phase.value} to {to} is not allowed")
        if new is not None:
            rec.phase = new

    # -- liveness -----------------------------------------------------------------
    def add(self, unit_id: str, owned: bool, now: float, reported: bool) -> UnitRecord:
        """A new unit's record; one made by anything but a report is stale from the start."""
        rec = self.records[unit_id] = UnitRecord(unit_id, unit_key(unit_id), owned=owned)
        self.version += 1
        if not reported:
            rec.stale = True
            rec.stale_since = now
            self.stale += 1
        self._to(rec, Step.MADE)
        return rec

    def reported(
        self,
        rec: UnitRecord,
        position: tuple[float, float],
        seq: int | None,
        kind: str | None,
        now: float,
        speed_mps: float,
    ) -> None:
        """A report: where the unit is, and proof of life whatever its token says; its push is answered."""
        moved = rec.stale or rec.position is None  # else the phase is as it was: no look at the table
        self.version += 1
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
        if rec.stepper is not None:
            rec.stepper.pace(speed_mps)
        if moved:
            self._to(rec, Step.REPORTED)

    def go_stale(self, rec: UnitRecord, now: float) -> bool:
        """Mark a unit that has reported stale; whether it was fresh until now."""
        if rec.stale or rec.position is None:
            return False
        rec.stale = True
        rec.stale_since = now
        self.stale += 1
        self.version += 1
        self._to(rec, Step.WENT_STALE)
        return True

    def forget(self, rec: UnitRecord) -> None:
        """Drop a unit's record, and its job with it."""
        self._to(rec, Step.FORGOTTEN, gone=True)
        self.version += 1
        self._supersede(rec)
        if self.records.pop(rec.id, None) is not None and rec.stale:
            self.stale -= 1

    def discard(self, rec: UnitRecord) -> None:
        """A record too broken to reset (the world's last resort): gone, with no look at its phase."""
        if self.records.pop(rec.id, None) is not None:
            self.stale -= rec.stale
            self.version += 1
            self.deliberating -= rec.job is not None

    # -- missions -----------------------------------------------------------------
    def set_goal(
        self, rec: UnitRecord, goal: Goal, shared: tuple[Goal, tuple[float, float], Resolved] | None
    ) -> None:
        """A goal set, or a mission restored (``shared``): a new epoch, its former mission and job gone."""
        self._drop(rec)
        rec.goal, rec.shared, rec.goal_gone = goal, shared, ""
        self.version += 1
        self._to(rec, Step.GOAL_SET)

    def drop_mission(self, rec: UnitRecord, why: str = "") -> None:
        """The unit's goal, mission, stepper and last verdict go; a new epoch starts, and its job is superseded.

        ``why`` (``GOAL_CANCELLED``, or words for a refusal or a fault) is the reason its ``no_goal``
        directions give until a goal is set again: a client puts its goal again on a ``no_goal`` that
        says nothing (a restarted planner), never on one that says it was cancelled.
        """
        self._drop(rec)
        rec.goal_gone = why
        self._to(rec, Step.GOAL_DROPPED)

    def started(self, rec: UnitRecord, mission: Started) -> None:
        """The unit's mission is fixed (``missions.start``): its ``x0`` and its stepper."""
        rec.shared, rec.stepper = mission.shared, mission.stepper
        rec.origin = mission.shared[1]
        self._to(rec, Step.STARTED)

    def share(self, rec: UnitRecord, mission: Mission) -> None:
        """Another planner fixed the unit's mission: kept for when this one takes the unit over."""
        params = Resolved(**msgspec.structs.asdict(mission.params))
        rec.shared = (mission.goal, (mission.origin[0], mission.origin[1]), params)

    def hand_over(self, rec: UnitRecord) -> None:
        """Another planner guides the unit now: this one keeps its mission, not its stepper."""
        rec.owned = False
        self._supersede(rec)
        rec.stepper = None
        rec.push = None
        rec.last_status = None
        self._to(rec, Step.HANDED_OVER)

    def take_over(self, rec: UnitRecord) -> None:
        """This planner guides the unit again (its mission is started by the world, from what was shared)."""
        rec.owned = True
        self._to(rec, Step.TAKEN_OVER)

    # -- steering and deliberation ------------------------------------------------
    def steered(self, rec: UnitRecord, verdict: Verdict) -> None:
        """Keep what the unit's direction said (``steering.direction``, ``steering.NO_GOAL``)."""
        moved = verdict.status is not rec.last_status  # the same verdict again: the phase stands
        rec.last_status, rec.last_reason, rec.last_distance, rec.last_vector = verdict
        if moved:
            self._to(rec, Step.STEERED)

    def yielded(self, rec: UnitRecord, verdict: Verdict) -> None:
        """The unit holds or makes room for another (dispersion's right of way): held on purpose, not trapped."""
        if rec.stepper is not None:
            rec.stepper.held()
        self.steered(rec, verdict)

    def asked(self, rec: UnitRecord, job: Job) -> None:
        """A deliberation job was asked for the unit."""
        rec.job = job
        self.deliberating += 1
        self._to(rec, Step.ASKED)

    def deliberated(self, rec: UnitRecord, done: Deliberated) -> Answer:
        """The unit's job came back: adopt what it found into the unit's stepper, if still in force."""
        if rec.job is None or rec.job.token != done.token:
            return Answer.IGNORED  # superseded: a newer goal or world is in force
        kind = rec.job.kind
        rec.job = None
        self.deliberating -= 1
        answer = Answer.QUIET
        st = rec.stepper
        if st is None or rec.token() != done.token:
            answer = Answer.IGNORED
        elif done.error is not None:
            answer = Answer.FAILED
        elif done.stepper is None and kind == "foresee":  # past its deadline: descend, and ask again
            st.look_ahead_again()  # at its next report, behind the queue
        elif done.stepper is None:
            st.pending = None  # a trap is asked again by the trap watch itself
        elif st.adopt(done.stepper):
            answer = Answer.TELL
        self._to(rec, Step.ANSWERED)
        return answer

    def classed(self, rec: UnitRecord, mobility: GoalMobility) -> None:
        """A state names the unit's class: kept, and a guided unit whose own slope limit or height it
        changes is re-judged (``rejudge``) under its new barriers (a class's, or an override's once held,
        ``world.slopes``; its class's safe side till then) and its new sight (``world.mobility``)."""
        before = slope_limit(rec.goal, rec.mobility), sight_height(rec.goal, rec.mobility)
        rec.mobility = mobility
        now = slope_limit(rec.goal, mobility), sight_height(rec.goal, mobility)
        if rec.owned and rec.stepper is not None and now != before:
            self.rejudge(rec)

    def rejudge(self, rec: UnitRecord) -> None:
        """Judge the unit's progress afresh under a new field; its job (asked under the old one) is superseded."""
        assert rec.stepper is not None
        rec.stepper.world_changed()
        if rec.job is not None:
            self._supersede(rec)
        self._to(rec, Step.WORLD_CHANGED)

    # -- inside the steps ---------------------------------------------------------
    def _drop(self, rec: UnitRecord) -> None:
        self.version += 1
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

    def _supersede(self, rec: UnitRecord) -> None:
        """The unit's job (if any) no longer counts; noted in ``superseded`` for whoever runs it."""
        job = rec.job
        if job is not None:
            self.superseded.append(job)
            rec.job = None
            self.deliberating -= 1
