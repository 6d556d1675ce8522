"""Every Zenoh key expression of the wire contract: built, parsed and subscribed here only.

No other module spells a topic string.  The layout (one mission per prefix):

    mumt/{m}/unit/{u}/state        unit -> planner      UnitState
    mumt/{m}/shard/{s}/unit/{u}/state  unit -> planner  UnitState, on its shard (s = shard_of(u))
    mumt/{m}/unit/{u}/goal         any -> planner       Goal (DELETE cancels)
    mumt/{m}/unit/{u}/direction    planner -> unit      Direction
    mumt/{m}/unit/{u}/mission      planner -> planners  Mission (x0 and parameters, for failover)
    mumt/{m}/threat/{t}            any -> planner       ThreatUpdate (DELETE removes)
    mumt/{m}/zone/{z}              any -> planner       ZoneUpdate (DELETE removes)
    mumt/{m}/team/{t}              any -> planner       TeamUpdate (DELETE dissolves)
    mumt/{m}/preview/{u}           queryable            PreviewRequest -> PlanResult
    mumt/{m}/preview/team/{t}      queryable            TeamPreviewRequest -> TeamPreview
    mumt/{m}/planner/{p}/status    queryable            -> PlannerStatus
    mumt/{m}/planner/{p}/world     queryable            -> WorldSnapshot (units, threats held)
    mumt/{m}/event/{kind}          planner -> any       Event
    mumt/{m}/alive/unit/{u}        liveliness token
    mumt/{m}/alive/planner/{p}     liveliness token

A unit state goes on either key; our clients use the shard key, so that each
planner of a cluster subscribes to its own shards only (``shard_of``: CRC-32
of the unit id's UTF-8 bytes, modulo ``SHARDS``).  Every variable part is one key chunk matching ``[A-Za-z0-9_-]{1,64}``, so a
wildcard ``*`` stands for exactly one of them and an ACL rule can name one
unit's keys (``mumt/m/unit/u7/**``).  Pure strings: no zenoh import.
"""

from __future__ import annotations

import re
import zlib
from enum import StrEnum
from typing import NamedTuple

from pfp_service.errors import InputError

__all__ = [
    "CHUNK_PATTERN",
    "DEFAULT_MISSION",
    "ID_NAMES",
    "MAX_KEY_CHARS",
    "PREFIX",
    "SHARDS",
    "SHARD_STATE_TEMPLATE",
    "TEMPLATES",
    "Key",
    "KeyKind",
    "KeyOf",
    "alive_planner",
    "alive_planners",
    "alive_unit",
    "alive_units",
    "check_chunk",
    "event",
    "events",
    "goals",
    "mission_all",
    "parse",
    "planner_status",
    "planner_statuses",
    "preview",
    "previews",
    "shard_of",
    "shard_state",
    "shard_states",
    "sharded_states",
    "team",
    "team_preview",
    "team_previews",
    "teams",
    "template",
    "threat",
    "threats",
    "unit_direction",
    "unit_directions",
    "unit_goal",
    "unit_mission",
    "unit_missions",
    "unit_state",
    "unit_states",
    "unit_states_any",
    "world",
    "worlds",
    "zone",
    "zones",
]

PREFIX = "mumt"
DEFAULT_MISSION = "default"
CHUNK_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"
_CHUNK = re.compile(CHUNK_PATTERN)
# The longest key of the layout is under 200 characters (two 64-character chunks); parse()
# refuses anything longer before matching it.
MAX_KEY_CHARS = 256


class KeyKind(StrEnum):
    """What a key is for; the value names its template in ``TEMPLATES``."""

    UNIT_STATE = "unit_state"
    UNIT_GOAL = "unit_goal"
    UNIT_DIRECTION = "unit_direction"
    UNIT_MISSION = "unit_mission"
    THREAT = "threat"
    PREVIEW = "preview"
    PLANNER_STATUS = "planner_status"
    EVENT = "event"
    ALIVE_UNIT = "alive_unit"
    ALIVE_PLANNER = "alive_planner"
    WORLD = "world"
    ZONE = "zone"
    TEAM = "team"
    TEAM_PREVIEW = "team_preview"


# ``{mission}`` and ``{id}`` are the only variables; the id is a unit, threat,
# planner or event kind depending on the template.  Published in schemas/index.json.
TEMPLATES: dict[KeyKind, str] = {
    KeyKind.UNIT_STATE: PREFIX + "/{mission}/unit/{id}/state",
    KeyKind.UNIT_GOAL: PREFIX + "/{mission}/unit/{id}/goal",
    KeyKind.UNIT_DIRECTION: PREFIX + "/{mission}/unit/{id}/direction",
    KeyKind.UNIT_MISSION: PREFIX + "/{mission}/unit/{id}/mission",
    KeyKind.THREAT: PREFIX + "/{mission}/threat/{id}",
    KeyKind.PREVIEW: PREFIX + "/{mission}/preview/{id}",
    KeyKind.PLANNER_STATUS: PREFIX + "/{mission}/planner/{id}/status",
    KeyKind.EVENT: PREFIX + "/{mission}/event/{id}",
    KeyKind.ALIVE_UNIT: PREFIX + "/{mission}/alive/unit/{id}",
    KeyKind.ALIVE_PLANNER: PREFIX + "/{mission}/alive/planner/{id}",
    KeyKind.WORLD: PREFIX + "/{mission}/planner/{id}/world",
    KeyKind.ZONE: PREFIX + "/{mission}/zone/{id}",
    KeyKind.TEAM: PREFIX + "/{mission}/team/{id}",
    KeyKind.TEAM_PREVIEW: PREFIX + "/{mission}/preview/team/{id}",
}

# What the ``{id}`` chunk names in each template, for people reading the layout.
ID_NAMES: dict[KeyKind, str] = {
    KeyKind.UNIT_STATE: "unit",
    KeyKind.UNIT_GOAL: "unit",
    KeyKind.UNIT_DIRECTION: "unit",
    KeyKind.UNIT_MISSION: "unit",
    KeyKind.THREAT: "threat",
    KeyKind.PREVIEW: "unit",
    KeyKind.PLANNER_STATUS: "planner",
    KeyKind.EVENT: "kind",
    KeyKind.ALIVE_UNIT: "unit",
    KeyKind.ALIVE_PLANNER: "planner",
    KeyKind.WORLD: "planner",
    KeyKind.ZONE: "zone",
    KeyKind.TEAM: "team",
    KeyKind.TEAM_PREVIEW: "team",
}


def template(kind: KeyKind) -> str:
    """The key template with readable variables, e.g. ``mumt/{mission}/unit/{unit}/state``."""
    return TEMPLATES[kind].replace("{id}", "{" + ID_NAMES[kind] + "}")


# Chunk patterns, from the templates, so parse() cannot drift from the builders.
_PARSERS: list[tuple[KeyKind, re.Pattern[str]]] = [
    (
        kind,
        re.compile(
            "^"
            + re.escape(t)
            .replace(re.escape("{mission}"), r"(?P<mission>[^/]+)")
            .replace(re.escape("{id}"), r"(?P<id>[^/]+)")
            + "$"
        ),
    )
    for kind, t in TEMPLATES.items()
]


class Key(NamedTuple):
    """A parsed key: what it is, its mission and its variable chunk (unit, threat, ...)."""

    kind: KeyKind
    mission: str
    id: str


def check_chunk(value: str, what: str = "id") -> str:
    """Return ``value`` if it is a valid key chunk, else raise.

    Raises:
        InputError: ``value`` is not 1-64 of ``[A-Za-z0-9_-]`` (so no ``/``, ``*``, ``$``).
    """
    if not isinstance(value, str) or not _CHUNK.match(value):
        raise InputError(what, f"{value!r} is not 1-64 characters of [A-Za-z0-9_-]")
    return value


def _build(kind: KeyKind, mission: str, id: str, what: str) -> str:
    return TEMPLATES[kind].format(mission=check_chunk(mission, "mission"), id=check_chunk(id, what))


def _wild(kind: KeyKind, mission: str) -> str:
    return TEMPLATES[kind].format(mission=check_chunk(mission, "mission"), id="*")


# -- shards: a unit state's partition, so K planners each receive 1/K of the states ----------
SHARDS = 16  # shards per mission, fixed (every client and planner must agree): a planner subscribes per shard
SHARD_STATE_TEMPLATE = PREFIX + "/{mission}/shard/{shard}/unit/{unit}/state"
_SHARD_HEAD = re.compile(r"^" + re.escape(PREFIX) + r"/([^/]+)/shard/(0|[1-9][0-9]{0,3})/unit/([^/]+)/state$")


def shard_of(unit: str) -> int:
    """The shard of a unit: CRC-32 (zlib, ISO-HDLC) of the id's UTF-8 bytes, modulo ``SHARDS``.

    Stable across processes, machines and languages (``zlib.crc32``, Go's
    ``crc32.ChecksumIEEE``): ``shard_of("ugv-1") == 15``.
    """
    return zlib.crc32(unit.encode()) % SHARDS


def shard_state(mission: str, unit: str) -> str:
    """``mumt/{mission}/shard/{shard_of(unit)}/unit/{unit}/state``: a unit's state on its shard."""
    return SHARD_STATE_TEMPLATE.format(
        mission=check_chunk(mission, "mission"), shard=shard_of(check_chunk(unit, "unit")), unit=unit
    )


def shard_states(mission: str, shard: int) -> str:
    """``mumt/{mission}/shard/{shard}/unit/*/state``: what the planner owning one shard subscribes to."""
    if not 0 <= shard < SHARDS:
        raise InputError("shard", f"{shard!r} is not a shard (0 to {SHARDS - 1})")
    return SHARD_STATE_TEMPLATE.format(mission=check_chunk(mission, "mission"), shard=shard, unit="*")


def sharded_states(mission: str) -> str:
    """``mumt/{mission}/shard/*/unit/*/state``: every shard (a planner owning them all)."""
    return SHARD_STATE_TEMPLATE.format(mission=check_chunk(mission, "mission"), shard="*", unit="*")


def unit_states_any(mission: str) -> str:
    """``mumt/{mission}/**/unit/*/state``: unit states on the plain key and on the shard keys (watchers)."""
    return f"{PREFIX}/{check_chunk(mission, 'mission')}/**/unit/*/state"


def parse_shard_state(key: str) -> tuple[str, int, str] | None:
    """``(mission, shard, unit)`` of a shard state key; ``None``: not one.

    Raises:
        InputError: path ``key``, when it is a shard key with a bad chunk or the wrong shard for its unit.
    """
    if len(key) > MAX_KEY_CHARS:
        return None
    m = _SHARD_HEAD.match(key)
    if m is None:
        return None
    mission, shard, unit = m[1], int(m[2]), m[3]
    if not _CHUNK.match(mission) or not _CHUNK.match(unit):
        raise InputError("key", f"{_shown(key)}: a chunk is not 1-64 characters of [A-Za-z0-9_-]")
    if shard != shard_of(unit):
        raise InputError("key", f"{_shown(key)}: unit {unit!r} is in shard {shard_of(unit)}, not {shard}")
    return mission, shard, unit


# -- concrete keys ------------------------------------------------------------
def unit_state(mission: str, unit: str) -> str:
    """``mumt/{mission}/unit/{unit}/state``: where a unit is (unit -> planner)."""
    return _build(KeyKind.UNIT_STATE, mission, unit, "unit")


def unit_goal(mission: str, unit: str) -> str:
    """``mumt/{mission}/unit/{unit}/goal``: where a unit should go; DELETE cancels."""
    return _build(KeyKind.UNIT_GOAL, mission, unit, "unit")


def unit_direction(mission: str, unit: str) -> str:
    """``mumt/{mission}/unit/{unit}/direction``: which way to go (planner -> unit)."""
    return _build(KeyKind.UNIT_DIRECTION, mission, unit, "unit")


def unit_mission(mission: str, unit: str) -> str:
    """``mumt/{mission}/unit/{unit}/mission``: a unit's fixed mission (planner -> planners)."""
    return _build(KeyKind.UNIT_MISSION, mission, unit, "unit")


def threat(mission: str, threat_id: str) -> str:
    """``mumt/{mission}/threat/{threat_id}``: a threat; DELETE removes it."""
    return _build(KeyKind.THREAT, mission, threat_id, "threat")


def zone(mission: str, zone_id: str) -> str:
    """``mumt/{mission}/zone/{zone_id}``: a keep-out zone; DELETE removes it."""
    return _build(KeyKind.ZONE, mission, zone_id, "zone")


def team(mission: str, team_id: str) -> str:
    """``mumt/{mission}/team/{team_id}``: a team and its roles; DELETE dissolves it."""
    return _build(KeyKind.TEAM, mission, team_id, "team")


def preview(mission: str, unit: str) -> str:
    """``mumt/{mission}/preview/{unit}``: the whole-path preview queryable."""
    return _build(KeyKind.PREVIEW, mission, unit, "unit")


def team_preview(mission: str, team_id: str) -> str:
    """``mumt/{mission}/preview/team/{team_id}``: the team preview queryable (every member's track)."""
    return _build(KeyKind.TEAM_PREVIEW, mission, team_id, "team")


def planner_status(mission: str, planner: str) -> str:
    """``mumt/{mission}/planner/{planner}/status``: health and counters queryable."""
    return _build(KeyKind.PLANNER_STATUS, mission, planner, "planner")


def event(mission: str, kind: str) -> str:
    """``mumt/{mission}/event/{kind}``: planner events (rejected, replan, trapped, arrived)."""
    return _build(KeyKind.EVENT, mission, kind, "event kind")


def alive_unit(mission: str, unit: str) -> str:
    """``mumt/{mission}/alive/unit/{unit}``: a unit's liveliness token."""
    return _build(KeyKind.ALIVE_UNIT, mission, unit, "unit")


def alive_planner(mission: str, planner: str) -> str:
    """``mumt/{mission}/alive/planner/{planner}``: a planner's liveliness token."""
    return _build(KeyKind.ALIVE_PLANNER, mission, planner, "planner")


def world(mission: str, planner: str) -> str:
    """``mumt/{mission}/planner/{planner}/world``: the units and threats a planner holds (queryable)."""
    return _build(KeyKind.WORLD, mission, planner, "planner")


# -- wildcards: one ``*`` per variable chunk, for subscribers and queryables ---
def unit_states(mission: str) -> str:
    """``mumt/{mission}/unit/*/state``."""
    return _wild(KeyKind.UNIT_STATE, mission)


def goals(mission: str) -> str:
    """``mumt/{mission}/unit/*/goal``."""
    return _wild(KeyKind.UNIT_GOAL, mission)


def unit_directions(mission: str) -> str:
    """``mumt/{mission}/unit/*/direction``."""
    return _wild(KeyKind.UNIT_DIRECTION, mission)


def unit_missions(mission: str) -> str:
    """``mumt/{mission}/unit/*/mission``."""
    return _wild(KeyKind.UNIT_MISSION, mission)


def threats(mission: str) -> str:
    """``mumt/{mission}/threat/*``."""
    return _wild(KeyKind.THREAT, mission)


def zones(mission: str) -> str:
    """``mumt/{mission}/zone/*``."""
    return _wild(KeyKind.ZONE, mission)


def teams(mission: str) -> str:
    """``mumt/{mission}/team/*``."""
    return _wild(KeyKind.TEAM, mission)


def previews(mission: str) -> str:
    """``mumt/{mission}/preview/*``: what a planner declares its preview queryable on."""
    return _wild(KeyKind.PREVIEW, mission)


def team_previews(mission: str) -> str:
    """``mumt/{mission}/preview/team/*``: what a planner declares its team preview queryable on."""
    return _wild(KeyKind.TEAM_PREVIEW, mission)


def planner_statuses(mission: str) -> str:
    """``mumt/{mission}/planner/*/status``: ask every planner of a mission."""
    return _wild(KeyKind.PLANNER_STATUS, mission)


def worlds(mission: str) -> str:
    """``mumt/{mission}/planner/*/world``: ask every planner of a mission what it holds."""
    return _wild(KeyKind.WORLD, mission)


def events(mission: str) -> str:
    """``mumt/{mission}/event/*``."""
    return _wild(KeyKind.EVENT, mission)


def alive_units(mission: str) -> str:
    """``mumt/{mission}/alive/unit/*``."""
    return _wild(KeyKind.ALIVE_UNIT, mission)


def alive_planners(mission: str) -> str:
    """``mumt/{mission}/alive/planner/*``."""
    return _wild(KeyKind.ALIVE_PLANNER, mission)


def mission_all(mission: str) -> str:
    """``mumt/{mission}/**``: everything of one mission (monitoring, ACL)."""
    return f"{PREFIX}/{check_chunk(mission, 'mission')}/**"


def parse(key: str) -> Key:
    """Split a concrete key into ``Key(kind, mission, id)``.

    Args:
        key: a key as received (``str(sample.key_expr)``); no wildcards.

    Raises:
        InputError: path ``key``, when the key is not in the layout or a chunk is invalid.
    """
    text = str(key)
    if len(text) > MAX_KEY_CHARS:  # before any matching: a hostile key may be megabytes long
        raise InputError("key", f"{_shown(text)} is longer than {MAX_KEY_CHARS} characters")
    sharded = parse_shard_state(text)
    if sharded is not None:  # a unit state on its shard: the same kind, the shard implied by the unit
        return Key(KeyKind.UNIT_STATE, sharded[0], sharded[2])
    for kind, pattern in _PARSERS:
        m = pattern.match(text)
        if m is not None:
            if not _CHUNK.match(m["mission"]) or not _CHUNK.match(m["id"]):
                raise InputError("key", f"{_shown(text)}: a chunk is not 1-64 characters of [A-Za-z0-9_-]")
            return Key(kind, m["mission"], m["id"])
    raise InputError("key", f"{_shown(text)} is not a key of the pfp wire contract")


class KeyOf:
    """The keys of one kind in one mission, without matching every pattern: for the hot paths.

    ``KeyOf(KeyKind.UNIT_STATE, "m").id(key)`` is ``parse(key).id`` for a
    unit state key (a subscriber knows which kind it gets), and ``key(unit)``
    builds one; both refuse what ``parse`` and the builders refuse.
    """

    __slots__ = ("_head", "_kind", "_mission", "_tail", "_what")

    def __init__(self, kind: KeyKind, mission: str) -> None:
        head, tail = TEMPLATES[kind].format(mission=check_chunk(mission, "mission"), id="\0").split("\0")
        self._head, self._tail, self._what = head, tail, ID_NAMES[kind]
        self._kind, self._mission = kind, mission

    def id(self, key: str) -> str:
        """The id chunk of a received key of this kind.

        Raises:
            InputError: as ``parse`` does, for any other key.
        """
        head, tail = self._head, self._tail
        if len(key) <= MAX_KEY_CHARS and key.startswith(head) and key.endswith(tail):
            ident = key[len(head) : len(key) - len(tail)]
            if _CHUNK.match(ident):
                return ident
        got = parse(key)  # the precise reason, or a key of another kind or mission
        if got.kind is self._kind and got.mission == self._mission:
            return got.id  # the same kind on another key of it: a unit state on its shard
        raise InputError(
            "key", f"{_shown(key)} is a {got.kind.value} key of mission {got.mission!r}, not {self}"
        )

    def __str__(self) -> str:
        return f"{self._head}*{self._tail}"

    def key(self, ident: str) -> str:
        """This kind's key for ``ident`` (checked as the builders check it)."""
        return self._head + check_chunk(ident, self._what) + self._tail


def _shown(text: str) -> str:
    """``repr(text)``, its middle left out past 100 characters, so a reason stays short."""
    if len(text) <= 100:
        return repr(text)
    return f"{text[:60]!r}...{text[-20:]!r} ({len(text)} characters)"
