"""One table of the world's input kinds: each names its key, mode, decoder, inputs, blame, store rows, log line, writers and schema.

A kind of input the world takes from the wire is one ``Kind`` in ``KINDS``.  What is written
out once per kind elsewhere is read from here: the node's subscriptions (``node.node._wire``, by
the kind's mode), its acknowledged-write queryables and their one generic handler
(``node.writes``), the durable state's tables, its commits, its read-back and the ``restored``
event's counts (``node.statefile``, ``node.store``, ``node.staterows``), the world snapshot's
``writes`` a joining planner learns it from (``held``, ``from_snapshot``), the log line of each
change (``node.log``), the key a failure is blamed on (``blame``), who may write each key under
access control (``node.access``), and the check of docs/wire.md's key table
(``tests/unit/test_kinds.py``).  A new kind is one entry here (its put and remove inputs, derived
from ``events.Written``, declared beside it) and one handler in ``World._apply_one``
(docs/development.md, "Add an input kind").

The mode says how the node reads a kind.  A ``write`` kind is put and deleted by anyone its roles
allow (goals, threats, zones, teams): decoded by the generic handler, committed before it is
applied, logged, restored at a restart.  The others: ``state``, unit states in rings (and the
planner's shards); ``token``, a liveliness token whose input is made from its id and whether it
came or went; ``peers``, the mission's planners' tokens (``node.twins.Peers``); ``shared``, what
planners share, read under ``--cluster`` only.  Pure values: no zenoh, no clock, no sqlite3 (a
table is named by its columns; ``node.store`` writes the SQL).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import msgspec

from pfp_service.core.params import Resolved
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import (
    Goal,
    UnitState,
    decode_goal,
    decode_mission,
    decode_threat,
    decode_unit_state,
    keys,
)
from pfp_service.wire.messages import TeamUpdate, decode_team, decode_zone
from pfp_service.wire.messages.structs import Bounds, ThreatUpdate
from pfp_service.wire.messages.world import WorldSnapshot
from pfp_service.world import mobility, translate
from pfp_service.world.events import (
    Deliberated,
    GoalCancelled,
    GoalSet,
    Input,
    InputRejected,
    MissionRestored,
    MissionShared,
    PeerPlanner,
    PeerTerrain,
    SightLanded,
    StateReported,
    TeamPut,
    TeamRemoved,
    ThreatPut,
    ThreatRemoved,
    TokenChanged,
    ZonePut,
    ZoneRemoved,
)

__all__ = [
    "BY_INPUT",
    "BY_NAME",
    "KINDS",
    "LISTED",
    "STORED",
    "WRITES",
    "WRITE_OF",
    "Held",
    "Kind",
    "LogLine",
    "Stored",
    "blame",
    "decode_state",
    "held",
    "ident",
    "inputs_from_snapshot",
    "log_line",
    "message",
    "rejected",
]

K = keys.KeyKind
Mode = Literal["write", "state", "token", "peers", "shared"]  # how the node reads it (``node._wire``)
Decoder = Callable[[bytes, Bounds | None, Origin | None], Any]
# the records of the write kinds listed by kind in the world snapshot: ``kind.id`` -> (kind, id, message, expires_at)
Held = Mapping[str, tuple[str, str, Any, float | None]]


@dataclass(frozen=True, slots=True)
class Stored:
    """A write kind's rows in the state database: one per id, ``body`` the encoded message.

    ``expiry``: ``never``; ``ttl``, the message's own ``ttl_s``; or ``ttl_or_default``, the
    service's default TTL when the message carries none.  Kept as the absolute Unix time
    ``expires_at``, so a restart honours the time that passed.  ``per_unit``: the id is a
    unit's, whose mission row a put or remove ends and which is restored with it (after the
    rest, since a mission is planned among the threats and zones in force).
    """

    table: str
    key_column: str
    expiry: Literal["never", "ttl", "ttl_or_default"] = "never"
    per_unit: bool = False

    @property
    def columns(self) -> tuple[str, ...]:
        return (self.key_column, "body", *(() if self.expiry == "never" else ("expires_at",)))


@dataclass(frozen=True, slots=True)
class LogLine:
    """One change as the log says it: ``what`` is the JSON line's stable message, ``msg % args`` the human
    one, ``at`` a position appended to ``args`` (shown in the mission's coordinates)."""

    what: str
    msg: str
    args: tuple[object, ...]
    fields: dict[str, object]
    at: Sequence[float] | None = None


@dataclass(frozen=True)
class Kind:
    """One kind of input: its key, its inputs, and what each part of the service does with it.

    Args:
        name: the kind's word in messages and logs (``goal``).
        key: its key in ``wire.keys``; the ``{id}`` chunk is the id of every input of it.
        mode: how the node reads it (module docstring).
        inputs: its world inputs (a write kind's put, then its remove; a token's or shared kind's
            one input), then any other input blamed on its key (a restored mission is a goal's).
            The first field of each is the id.
        blames_unit: the id is a unit's, whose goal goes when applying one of these fails.
        schema: its message's name in ``wire.schema.MESSAGES`` (``None``: no payload).
        decode: payload, bounds, origin -> message; raises ``InputError``.
        writers: the access-control roles that may put and delete it (``node.access.ROLES``).
        own_unit: each unit may also write its own key (unless ``pfp acl --no-unit-goals``).
        store: its rows in the state database (``None``: not kept).
        log_put, log_remove: the log line of a put (id, message) and of a remove (id).
        held: a write kind's records in force, read from the ``World``: id -> (message, expires_at).
            Listed by kind in the world snapshot's ``writes``, so a joining planner learns them
            (``None``: the snapshot lists it its own way: goals with their units, threats, zones).
    """

    name: str
    key: keys.KeyKind
    mode: Mode
    inputs: tuple[type[Any], ...]
    blames_unit: bool = False
    schema: str | None = None
    decode: Decoder | None = None
    writers: tuple[str, ...] = ()
    own_unit: bool = False
    store: Stored | None = None
    log_put: Callable[[str, Any], LogLine] | None = None
    log_remove: Callable[[str], LogLine] | None = None
    held: Callable[[Any], Mapping[str, tuple[Any, float | None]]] | None = None

    @property
    def put(self) -> type[Any]:
        """Its first input, ``put(id, message)``: a write kind's put, a token's ``(id, alive)``, a shared record."""
        return self.inputs[0]

    @property
    def remove(self) -> type[Any]:
        """A write kind's remove input, ``remove(id)``: a DELETE on its key."""
        return self.inputs[1]

    def wildcard(self, mission: str) -> str:
        """Its key with ``*`` for the id: what the planner subscribes to."""
        return str(keys.KeyOf(self.key, mission))

    def key_of(self, mission: str, ident: str) -> str:
        """Its key for ``ident`` (checked as ``wire.keys``' builders check it)."""
        return keys.KeyOf(self.key, mission).key(ident)

    def make(
        self, ident: str, delete: bool, payload: bytes, bounds: Bounds | None, origin: Origin | None
    ) -> Input:
        """A write (or shared) kind's input for a put (``payload`` decoded) or a DELETE of ``ident``.

        Raises:
            InputError: the payload does not decode.
        """
        if delete:
            return self.remove(ident)  # type: ignore[no-any-return]
        assert self.decode is not None
        return self.put(ident, self.decode(payload, bounds, origin))  # type: ignore[no-any-return]


def _decode_threat(data: bytes, bounds: Bounds | None, origin: Origin | None) -> ThreatUpdate:
    """The wire's decoder, then its shape's checks: a threat this planner cannot plan is refused unstored.

    Raises:
        InputError: ``$.shape`` or ``$.params.<name>`` (``translate.check``), or as ``decode_threat``.
    """
    update = decode_threat(data, bounds, origin)
    try:
        translate.check(update)
    except translate.ShapeError as exc:
        raise translate.refusal(exc) from exc
    return update


def _decode_goal(data: bytes, bounds: Bounds | None, origin: Origin | None) -> Goal:
    """The wire's decoder, then its mobility class's check (``world.mobility``): an unknown class is refused."""
    return mobility.check(decode_goal(data, bounds, origin))


def decode_state(data: bytes, bounds: Bounds | None, origin: Origin | None) -> UnitState:
    """The wire's decoder, then its mobility class's check (``world.mobility``): a state naming an unknown
    class is refused whole, as a goal is (a state without one pays one attribute read)."""
    return mobility.check(decode_unit_state(data, bounds, origin))


def _decode_team(data: bytes, bounds: Bounds | None, origin: Origin | None) -> TeamUpdate:
    """The wire's decoder, then its goal's mobility class's check: refused on ``$.goal.mobility...`` whole,
    not once per member when each is given its place."""
    team = decode_team(data, bounds, origin)
    refused = mobility.refusal(team.goal) if team.goal is not None else None
    if refused is not None:
        raise InputError("$.goal" + refused.path[1:], refused.reason)
    return team


_FIELDS: dict[type[Any], tuple[str, ...]] = {}  # an input class's field names, looked up once


def _field_names(cls: type[Any]) -> tuple[str, ...]:
    names = _FIELDS.get(cls)
    if names is None:
        names = _FIELDS[cls] = tuple(f.name for f in dataclasses.fields(cls))
    return names


def ident(inp: Input) -> str:
    """The id an input of a kind names (its first field: a unit, a threat, a zone, a planner)."""
    return str(getattr(inp, _field_names(type(inp))[0]))


def message(inp: Input) -> Any:
    """A put's message (its second field: the goal, the threat or zone update)."""
    return getattr(inp, _field_names(type(inp))[1])


def _goal_set(unit: str, goal: Any) -> LogLine:
    return LogLine(
        "goal set",
        "goal of %s set to %s",
        (unit,),
        {"unit": unit, "goal": list(goal.position)},
        goal.position,
    )


def _threat_put(threat: str, update: Any) -> LogLine:
    pos = update.position
    return LogLine(
        "threat put", "threat %s put at %s", (threat,), {"threat": threat, "position": list(pos)}, pos
    )


def _zone_put(zone: str, z: Any) -> LogLine:
    if z.circle is not None:
        shape, first = f"circle of {z.circle.radius_m:g} m at", z.circle.centre
    else:
        shape, first = (
            f"polygon of {len((z.polygon or [[]])[0]) - 1} corners from",
            (z.polygon or [[(0.0, 0.0)]])[0][0],
        )
    return LogLine(
        "zone put", "keep-out zone %s put: %s %s", (zone, shape), {"zone": zone, "kind": z.kind}, first
    )


def _team_put(team: str, t: Any) -> LogLine:
    units = list(t.units())
    return LogLine("team put", "team %s put: %s", (team, ", ".join(units)), {"team": team, "units": units})


def _gone(what: str, msg: str, name: str) -> Callable[[str], LogLine]:
    return lambda ident: LogLine(what, msg, (ident,), {name: ident})


KINDS: tuple[Kind, ...] = (
    Kind(
        "goal",
        K.UNIT_GOAL,
        "write",
        (GoalSet, GoalCancelled, MissionRestored, Deliberated),
        blames_unit=True,
        schema="goal",
        decode=_decode_goal,
        writers=("commander",),
        own_unit=True,
        store=Stored("goals", "unit", per_unit=True),
        log_put=_goal_set,
        log_remove=_gone("goal cancelled", "goal of %s cancelled", "unit"),
    ),
    Kind(
        "threat",
        K.THREAT,
        "write",
        (ThreatPut, ThreatRemoved, SightLanded),
        schema="threat",
        decode=_decode_threat,
        writers=("reporter",),
        store=Stored("threats", "id", expiry="ttl_or_default"),
        log_put=_threat_put,
        log_remove=_gone("threat removed", "threat %s removed", "threat"),
    ),
    Kind(
        "zone",
        K.ZONE,
        "write",
        (ZonePut, ZoneRemoved),
        schema="zone",
        decode=decode_zone,
        writers=("reporter",),
        store=Stored("zones", "id", expiry="ttl"),
        log_put=_zone_put,
        log_remove=_gone("zone removed", "keep-out zone %s removed", "zone"),
    ),
    Kind(
        "team",
        K.TEAM,
        "write",
        (TeamPut, TeamRemoved),
        schema="team",
        decode=_decode_team,
        writers=("commander",),
        store=Stored("teams", "id"),
        log_put=_team_put,
        log_remove=_gone("team dissolved", "team %s dissolved", "team"),
        held=lambda world: {tid: (team, None) for tid, team in world.teams.teams.items()},
    ),
    Kind(
        "unit state",
        K.UNIT_STATE,
        "state",
        (StateReported,),
        blames_unit=True,
        schema="unit_state",
        decode=decode_state,
        own_unit=True,
    ),
    Kind("unit token", K.ALIVE_UNIT, "token", (TokenChanged,), own_unit=True),
    Kind("planner token", K.ALIVE_PLANNER, "peers", (PeerPlanner, PeerTerrain), writers=("planner",)),
    Kind(
        "mission",
        K.UNIT_MISSION,
        "shared",
        (MissionShared,),
        blames_unit=True,
        schema="mission",
        decode=lambda data, _bounds, _origin: decode_mission(data),
        writers=("planner",),
    ),
)

WRITES: tuple[Kind, ...] = tuple(k for k in KINDS if k.mode == "write")
BY_INPUT: dict[type[Any], Kind] = {cls: k for k in KINDS for cls in k.inputs}
BY_NAME: dict[str, Kind] = {k.name: k for k in KINDS}
LISTED: tuple[Kind, ...] = tuple(k for k in WRITES if k.held is not None)  # in the snapshot's ``writes``
# the write kinds kept in the state database, a unit's (goals) after the rest: its tables are made, salvaged
# and read back in this order (a restored mission is planned among the threats and zones in force)
STORED: tuple[Kind, ...] = tuple(
    sorted((k for k in WRITES if k.store is not None), key=lambda k: bool(k.store and k.store.per_unit))
)
# a write kind's put and remove inputs -> (its kind, whether a put): what is stored, logged and refused
WRITE_OF: dict[type[Any], tuple[Kind, bool]] = {
    cls: (k, cls is k.put) for k in WRITES for cls in (k.put, k.remove)
}


def blame(inp: Input, mission: str) -> tuple[str, str | None, keys.KeyKind | None]:
    """The key an input came on (where a failure to apply it is rejected), the unit whose goal goes with it, and the key's kind.

    The key is spelled from the layout even for an id ``keys`` would refuse; a
    ``Tick`` is blamed on the mission's event key.
    """
    if isinstance(inp, InputRejected):
        return inp.key, None, inp.kind
    kind = BY_INPUT.get(type(inp))
    if kind is None:
        return keys.TEMPLATES[K.EVENT].format(mission=mission, id="tick"), None, K.EVENT
    got = ident(inp)
    return (
        keys.TEMPLATES[kind.key].format(mission=mission, id=got),
        got if kind.blames_unit else None,
        kind.key,
    )


def rejected(inp: Input, mission: str, error: InputError) -> Input:
    """A write's input refused as a whole (the store could not keep it): an ``InputRejected`` on its key; the rest as it is."""
    got = WRITE_OF.get(type(inp))
    if got is None or got[0].store is None:
        return inp
    return InputRejected(got[0].key_of(mission, ident(inp)), error, got[0].key)


def log_line(inp: object) -> LogLine | None:
    """The log line of a write's input (``None``: not a change the log says)."""
    got = WRITE_OF.get(type(inp))
    if got is None:
        return None
    kind, put = got
    if put:
        return kind.log_put(ident(inp), message(inp)) if kind.log_put is not None else None  # type: ignore[arg-type]
    return kind.log_remove(ident(inp)) if kind.log_remove is not None else None  # type: ignore[arg-type]


def held(world: Any) -> Held:
    """The records of the write kinds listed by kind (``LISTED``) in ``world``, for the snapshot's ``writes``."""
    return {
        f"{k.name}.{ident}": (k.name, ident, msg, expires_at)
        for k in LISTED
        if k.held is not None
        for ident, (msg, expires_at) in k.held(world).items()
    }


def inputs_from_snapshot(snap: WorldSnapshot, me: str) -> list[Input]:
    """What a peer planner's world page says, as inputs: its writes listed by kind (``LISTED``: teams),
    zones and threats (with the time left), goals and missions.

    A planner started after threats and goals were published applies these and guides correctly
    from its first direction.  Its own page is skipped.  A listed kind this planner does not know
    (a newer planner's) is skipped; a body its kind's decoder refuses is an ``InputRejected`` on
    its key.  A planner older than ``writes`` gives its teams in ``teams``.
    """
    if snap.planner == me:
        return []
    inputs: list[Input] = [TeamPut(t.id, t.team) for t in snap.teams] if not snap.writes_total else []
    for w in snap.writes:
        kind = BY_NAME.get(w.kind)
        if kind is None or kind.held is None or kind.decode is None:
            continue
        try:
            msg = kind.decode(msgspec.json.encode(w.body), None, None)
        except InputError as err:
            inputs.append(InputRejected(kind.key_of(snap.mission, w.id), err, kind.key))
            continue
        inputs.append(kind.put(w.id, _time_left(msg, w.ttl_s)))
    inputs += [ZonePut(z.id, _time_left(z.zone, z.ttl_s)) for z in snap.zones]
    inputs += [ThreatPut(t.id, _time_left(t.threat, t.ttl_s)) for t in snap.threats]
    for u in snap.units:
        if u.mission is not None:
            params = Resolved(**msgspec.structs.asdict(u.mission.params))
            origin = (u.mission.origin[0], u.mission.origin[1])
            inputs.append(MissionRestored(u.id, u.mission.goal, origin, params))
        elif u.goal is not None:
            inputs.append(GoalSet(u.id, Goal(position=u.goal)))
    return inputs


def _time_left(msg: Any, ttl_s: float | None) -> Any:
    """A peer's message with the time it has left as its own ``ttl_s`` (``None``: it does not expire)."""
    return msg if ttl_s is None else msgspec.structs.replace(msg, ttl_s=max(ttl_s, 1e-3))
