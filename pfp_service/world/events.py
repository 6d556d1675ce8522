"""What goes into ``World.apply`` and what comes out: the world's inputs, outputs and settings.

Inputs are one tagged union of frozen dataclasses (``Input``), each carrying
its ids; ``Outputs`` holds the directions, events, deliberation jobs and
missions one ``apply`` returns.  Pure values: no zenoh, no clock.
"""

from __future__ import annotations

import copy
import dataclasses
import traceback
import zlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Union

from pfp_service.core.params import PlannerParams, Resolved
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import (
    Direction,
    Event,
    Goal,
    Mission,
    MissionParams,
    ThreatChange,
    ThreatUpdate,
    UnitState,
    keys,
)
from pfp_service.wire.messages import GoalMobility, TeamUpdate, TerrainInfo, ZoneCircle, ZoneUpdate
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.terrain import SightAsk, SightLanded, SlopeAsk, SlopeLanded

if TYPE_CHECKING:  # the compiled core's types: loaded by the planner, not by whoever reads the kinds' table
    from pfp_service.core import Stepper, Threat, ThreatField
    from pfp_service.core.zones import Zone, ZoneSet
    from pfp_service.world.terrain import Ground

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
    "PeerTerrain",
    "SightAsk",
    "SightLanded",
    "SlopeAsk",
    "SlopeLanded",
    "StateReported",
    "TeamPut",
    "TeamRemoved",
    "ThreatPut",
    "ThreatRemoved",
    "Tick",
    "TokenChanged",
    "UnitView",
    "WorldSettings",
    "Written",
    "ZonePut",
    "ZoneRemoved",
    "mission_message",
    "mission_of",
    "unit_key",
    "where",
    "zone_put",
]


def where(exc: BaseException) -> str:
    """The innermost frame of ``exc`` as ``package/module.py:line``: one line in a log, never a traceback."""
    frames = traceback.extract_tb(exc.__traceback__)
    if not frames:
        return "?"
    f = frames[-1]
    path = f.filename.replace("\\", "/")
    cut = path.rfind("pfp_service/")
    return f"{path[cut + len('pfp_service/') :] if cut >= 0 else path.rsplit('/', 1)[-1]}:{f.lineno}"


def unit_key(unit_id: str) -> int:
    """The seed of a unit's random escapes: stable across restarts, previews and planners."""
    return zlib.crc32(unit_id.encode())


# -- inputs -------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Written:
    """A write kind's put or remove (``world.kinds.WRITES``): the id first, a put's message second.

    Every write input derives from it, and ``Input`` names this base rather than each class,
    so a new kind's inputs, declared beside its entry in ``world.kinds``, need no edit here.
    """


@dataclass(frozen=True, slots=True)
class StateReported:
    """A unit said where it is (``unit/{u}/state``)."""

    unit: str
    state: UnitState


@dataclass(frozen=True, slots=True)
class GoalSet(Written):
    unit: str
    goal: Goal


@dataclass(frozen=True, slots=True)
class GoalCancelled(Written):
    unit: str


@dataclass(frozen=True, slots=True)
class ThreatPut(Written):
    threat: str
    update: ThreatUpdate


@dataclass(frozen=True, slots=True)
class ThreatRemoved(Written):
    threat: str


@dataclass(frozen=True, slots=True)
class ZonePut(Written):
    """A keep-out zone put (``zone/{z}``): new, or moved or reshaped if the id is known."""

    zone: str
    update: ZoneUpdate


@dataclass(frozen=True, slots=True)
class ZoneRemoved(Written):
    zone: str


@dataclass(frozen=True, slots=True)
class TeamPut(Written):
    """A team put (``team/{t}``): new, or its members and roles changed if the id is known."""

    team: str
    update: TeamUpdate


@dataclass(frozen=True, slots=True)
class TeamRemoved(Written):
    team: str


def zone_put(zone: Zone) -> ZonePut:
    """A core ``Zone`` (a ``--zones`` file's, ``geojson.load_zones``) as the input a wire put of it makes."""
    if zone.centre is not None:
        circle = ZoneCircle(centre=zone.centre, radius_m=zone.radius_m)
        return ZonePut(zone.id, ZoneUpdate(kind=zone.kind, circle=circle))
    rings = [[*ring, ring[0]] for ring in zone.rings()]
    return ZonePut(zone.id, ZoneUpdate(kind=zone.kind, polygon=rings))


@dataclass(frozen=True, slots=True)
class TokenChanged:
    """A unit's liveliness token appeared (``alive``) or went."""

    unit: str
    alive: bool


@dataclass(frozen=True, slots=True)
class InputRejected:
    """A message that failed to decode: the world counts it and says so, rate-limited.

    ``kind``: its key's kind, known wherever the key itself parsed (``None``: the key is not of
    the layout); its rejections are paced with that kind's (``Limits.reject``).
    """

    key: str
    error: InputError
    kind: keys.KeyKind | None = None


@dataclass(frozen=True, slots=True)
class Deliberated:
    """A finished ``Job``: ``stepper`` is its copy after ``deliberate()`` (``None``: past its deadline).

    ``error`` says why it failed instead, as ``(class, message, where)``
    (``Job.run`` never raises): the world drops that unit's goal and rejects it.
    """

    unit: str
    token: tuple[int, int]
    stepper: Stepper | None
    error: tuple[str, str, str] | None = None


@dataclass(frozen=True, slots=True)
class MissionRestored:
    """A unit's mission from durable state: its goal, ``x0`` and resolved parameters, as fixed before."""

    unit: str
    goal: Goal
    origin: tuple[float, float]
    params: Resolved


@dataclass(frozen=True, slots=True)
class MissionShared:
    """Another planner fixed a unit's mission (``unit/{u}/mission``): kept for when this one takes it over."""

    unit: str
    mission: Mission


@dataclass(frozen=True, slots=True)
class PeerPlanner:
    """Another planner's liveliness token on this mission appeared (``alive``) or went.

    ``session`` names a twin: a planner serving this one's own id from
    another Zenoh session (``planner`` is then ``{id}-{session}``).
    """

    planner: str
    alive: bool
    session: str | None = None


@dataclass(frozen=True, slots=True)
class PeerTerrain:
    """Planner ``planner`` of this mission plans over ``theirs`` (``None``: no terrain), this one over ``mine``,
    as their statuses say (``node.duplicates.watch_duplicates``): the world decides whether they can share units."""

    planner: str
    theirs: TerrainInfo | None
    mine: TerrainInfo | None


@dataclass(frozen=True, slots=True)
class Tick:
    """Time passed: run the timers due by ``now``.

    ``shed`` counts the inputs the node refused at its bounded queues since
    its last tick (a flood past ``INBOX_MAX``, a query flood): the world keeps
    the one ``overload`` count, of these and of its own limits.
    """

    now: float
    shed: int = 0


Input = Union[  # noqa: UP007
    StateReported,
    Written,  # every write kind's put and remove: GoalSet, ThreatPut, ZoneRemoved, TeamPut, ...
    TokenChanged,
    InputRejected,
    Deliberated,
    MissionRestored,
    MissionShared,
    PeerPlanner,
    PeerTerrain,
    SightLanded,
    SlopeLanded,
    Tick,
]


# -- outputs ------------------------------------------------------------------------
@dataclass(slots=True)
class Job:
    """Deliberation for one unit, to run off the planning loop.

    ``run()`` needs nothing from the world: it works on a detached copy of the
    unit's stepper under the field in force when it was asked.  Once it is
    returned the world never touches it again: when a newer goal or world
    supersedes it, the job is listed in ``Outputs.cancelled``, and its driver
    sets ``cancelled`` so a pool can skip it; a late result is discarded by
    its ``token`` in any case.
    """

    unit: str
    token: tuple[int, int]
    kind: str
    stepper: Stepper
    field: ThreatField
    deadline: float
    cancelled: bool = False
    live: bool = False  # ``stepper`` is the unit's own still: ``detach`` copies it

    def detach(self) -> Stepper:
        """The job's own copy of the stepper, made at the first call (lazily: off ``World.apply``'s wave).

        The world hands the live stepper over and the copy is made when the
        job is sent or run, on the loop thread; a job superseded before that
        costs no copy.  The copy asks what was asked (``pending`` as at the
        ask), and a result for a goal or world no longer in force is dropped
        by its ``token`` as ever.
        """
        if self.live:
            need = self.stepper.pending
            self.stepper = copy.deepcopy(self.stepper)
            if need is None or need.kind != self.kind or self.stepper.version != self.token[1]:
                self.stepper.pending = None  # answered or superseded meanwhile: nothing to run
            self.live = False
        return self.stepper

    def run(self, now: float | None = None) -> Deliberated:
        """Deliberate; ``now`` past the deadline gives up without computing."""
        if now is not None and now > self.deadline:
            return Deliberated(self.unit, self.token, None)
        self.detach()
        try:
            self.stepper.deliberate(self.field)
        except Exception as exc:  # a failure as a value: the world drops this unit's goal, no one else's
            return Deliberated(self.unit, self.token, None, (type(exc).__name__, str(exc)[:200], where(exc)))
        return Deliberated(self.unit, self.token, self.stepper)


@dataclass(frozen=True, slots=True)
class MissionRecord:
    """A unit's mission was fixed (its first report after a goal): what durable state must keep."""

    unit: str
    epoch: int
    origin: tuple[float, float]
    goal: Goal
    params: Resolved


@dataclass(frozen=True, slots=True)
class Fault:
    """Applying an input (or a timer, or one unit's step) failed inside the world: what to log, once.

    The world already dropped what failed and sent a ``rejected`` event; this
    is for the operator's log, at most once a minute per key (``suppressed``
    counts the faults on that key not logged since), and never a traceback.
    """

    key: str  # the key of the input, or of the unit or threat a timer or step was for
    error: str  # the exception's class, e.g. ``ZeroDivisionError``
    detail: str  # its message, cut short
    where: str  # the innermost frame, ``core/params.py:150``
    suppressed: int = 0

    def fields(self) -> dict[str, object]:
        """The log line's fields."""
        return {
            "key": self.key,
            "error": self.error,
            "detail": self.detail,
            "where": self.where,
            "suppressed": self.suppressed,
        }


@dataclass(slots=True)
class Outputs:
    """What one ``apply`` must send: directions, events, deliberation jobs, missions to record, faults to log."""

    directions: list[Direction] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    jobs: list[Job] = field(default_factory=list)
    missions: list[MissionRecord] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
    cancelled: list[Job] = field(default_factory=list)  # jobs returned before and no longer wanted
    sights: list[SightAsk] = field(default_factory=list)  # threats' windows to compute off the loop
    slopes: list[SlopeAsk] = field(default_factory=list)  # override slope limits' barriers, ditto

    def __bool__(self) -> bool:
        return bool(
            self.directions or self.events or self.jobs or self.missions or self.faults or self.cancelled
        ) or bool(self.sights or self.slopes)

    def extend(self, other: Outputs) -> None:
        """Append ``other``'s outputs to these (a second ``apply`` in one of the driver's ticks)."""
        for f in dataclasses.fields(self):
            getattr(self, f.name).extend(getattr(other, f.name))


@dataclass(slots=True)
class Batch:
    """One ``World.apply`` as it runs: its clock, what goes out, the units to direct, and the threats changed."""

    now: float
    out: Outputs = field(default_factory=Outputs)
    dirty: set[str] = field(default_factory=set)  # units to get a fresh direction
    changes: list[ThreatChange] = field(default_factory=list)
    touched: list[Threat] = field(default_factory=list)  # threats put, moved or gone (old and new)
    zones: list[tuple[str, str, tuple[float, float, float, float]]] = field(default_factory=list)
    # ^ zones put, moved or gone: (id, change, box), the old box and the new for a zone moved
    wave: set[str] = field(
        default_factory=set
    )  # units sent their direction first, the rest in the next apply
    shared: int = 0  # a wave's units drawn to be told in this apply (``World._shares``)
    # ``wave.Judged``: threats landed, their reach judged off the loop; ``wave.Corridors``: the units'
    # corridors, taken at the batch's first sight asked (a storm of puts shares them)
    judged: list[Any] = field(default_factory=list)
    corridors: Any = None


def _no_zones() -> ZoneSet:
    from pfp_service.core.zones import ZoneSet

    return ZoneSet()


@dataclass(frozen=True, slots=True)
class UnitView:
    """A detached copy of one unit and the threats in force, for a preview off the loop."""

    unit: str
    position: tuple[float, float] | None
    goal: Goal | None
    origin: tuple[float, float] | None
    stepper: Stepper | None
    threats: tuple[Threat, ...]
    settings: WorldSettings
    last_vector: tuple[float, float] | None = None  # the direction given at ``position``, if moving
    zones: ZoneSet = field(
        default_factory=_no_zones
    )  # the keep-out zones in force: a preview never enters one
    height_m: float | None = None  # over terrain, the height threats see it at (None: the planner's class's)
    standing: GoalMobility | None = None  # the mobility its states name (``world.mobility``)

    def params_for(self, goal: Goal) -> PlannerParams:
        return self.settings.params_for(goal)


@dataclass(frozen=True)
class WorldSettings:
    """What the world model needs from the service configuration."""

    planner: PlannerParams = field(default_factory=PlannerParams)
    threat_ttl_s: float | None = None  # default TTL for threats that carry none
    unit_stale_s: float = 10.0  # silence after which a unit is stale
    liveliness_debounce_s: float = 2.0  # a token DELETE counts after this long
    lookahead: int = 5  # predicted positions per direction
    bounds: tuple[tuple[float, float], tuple[float, float]] | None = None  # mission bounds
    mission: str = keys.DEFAULT_MISSION
    planner_id: str = "planner"
    deliberation: Literal["inline", "deferred"] = "inline"
    deliberation_budget_s: float = 5.0  # a job not started by then is dropped
    unit_forget_s: float | None = 600.0  # stale this long: forgotten (None: never)
    max_units: int = 100_000
    max_threats: int = 10_000
    max_zones: int = 1_000  # keep-out zones held at most (each up to 4,096 vertices)
    push_retry_s: float = 0.25  # a push (a direction no report asked for) is sent again after this
    push_retries: int = 4  # ... this many times, until the unit's next report is answered
    cluster: bool = False  # scale-out configured: other planners are peers, not a conflict
    origin: Origin | None = None  # the mission origin: directions also carry true bearing and lat/lon
    terrain: Ground | None = None  # the DEM planned over (``world.terrain``): sight and slope barriers
    sight_wait_s: float = (
        0.25  # a threat over terrain held this long for its window, then blind (``world.terrain``)
    )
    dispersion: DispersionSettings = field(default_factory=DispersionSettings)  # off unless enabled

    def params_for(self, goal: Goal) -> PlannerParams:
        """A unit's planner parameters: service defaults, then the goal's overrides."""
        if goal.delta is None and goal.tolerance is None and goal.step is None:
            return self.planner  # the common case, and a storm of 10,000 goals pays no copies
        return self.planner.merged(delta=goal.delta, tolerance=goal.tolerance, step=goal.step)


def mission_of(
    shared: tuple[Goal, tuple[float, float], Resolved] | None, planner: str | None
) -> Mission | None:
    """A unit's fixed mission on the wire (``None`` until it is fixed)."""
    if shared is None:
        return None
    goal, origin, params = shared
    wire = MissionParams(**{k: getattr(params, k) for k in MissionParams.__struct_fields__})
    return Mission(goal=goal, origin=origin, params=wire, planner=planner)


def mission_message(record: MissionRecord, planner: str) -> Mission:
    """What the node publishes on ``unit/{u}/mission`` for a record of ``Outputs.missions``."""
    m = mission_of((record.goal, record.origin, record.params), planner)
    assert m is not None
    return m
