"""What planners share: a unit's mission as its planner fixed it, and the world queryable's pages.

Apart from the messages between a unit and its planner (``structs``), which these build on.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Any

import msgspec
from msgspec import Meta

from pfp_service.constraints import Id, Iterations, NonNegative, Point, Positive
from pfp_service.wire.messages.structs import (
    MAX_SNAPSHOT_ITEMS,
    Count,
    DirectionStatus,
    Goal,
    Text,
    ThreatUpdate,
    UnitKind,
    ZoneUpdate,
    _Message,
)
from pfp_service.wire.messages.teams import MAX_TEAM_MEMBERS, TeamUpdate

__all__ = [
    "Mission",
    "MissionParams",
    "TeamSummary",
    "ThreatSummary",
    "UnitPhase",
    "UnitSummary",
    "WorldQuery",
    "WorldSnapshot",
    "WriteCursor",
    "WriteSummary",
    "ZoneSummary",
]

# where a page's ``writes`` go on: ``{kind}.{id}`` (a kind's name and an id are key chunks, with no ``.``)
WriteCursor = Annotated[str, Meta(pattern=r"^[A-Za-z0-9_-]{1,64}\.[A-Za-z0-9_-]{1,64}$")]


class ZoneSummary(_Message, frozen=True, kw_only=True):
    """One zone in force (``WorldSnapshot.zones``); ``ttl_s`` is the time left, null: no expiry."""

    id: Id
    zone: ZoneUpdate
    ttl_s: NonNegative | None = None


# -- shared between planners -----------------------------------------------------
class MissionParams(_Message, frozen=True, kw_only=True):
    """The planner parameters resolved for one unit's goal (``core.params.Resolved``)."""

    delta: Positive
    step: Positive
    max_iter: Iterations
    tolerance: Positive
    intensity: Annotated[str, Meta(pattern="^(peak|density)$")]
    escape: Annotated[str, Meta(pattern="^[a-z]{1,16}$")]
    trap_window: Annotated[int, Meta(ge=2, le=1_000_000)]
    progress_window: Annotated[int, Meta(ge=2, le=10_000_000)]
    seed: Annotated[int, Meta(ge=0, le=2**63 - 1)] = 0


class Mission(_Message, frozen=True, kw_only=True):
    """A unit's mission as fixed by its planner: published on ``mumt/{m}/unit/{u}/mission``.

    Planners that share a mission keep it, so whichever owns the unit next
    guides it from the same ``x0`` and parameters.
    """

    goal: Goal
    origin: Point
    params: MissionParams
    planner: Id | None = None


# -- the world queryable ---------------------------------------------------------
class UnitPhase(StrEnum):
    """Where a unit is in its life, as its planner holds it (``UnitSummary.phase``; ``world.units``)."""

    UNKNOWN = "unknown"  # named (by a goal, a mission, a peer) but never heard from
    STALE = "stale"  # heard from, then silent or its liveliness token gone: told nothing
    PEER = "peer"  # another planner of the cluster guides it
    NO_GOAL = "no_goal"
    GUIDED = "guided"  # en route or escaping
    DELIBERATING = "deliberating"  # guided, with a look-ahead or an escape search asked
    ARRIVED = "arrived"
    TRAPPED = "trapped"


class UnitSummary(_Message, frozen=True, kw_only=True):
    """One unit as the planner holds it (``WorldSnapshot.units``)."""

    id: Id
    kind: UnitKind | None = None
    status: DirectionStatus | None = None
    position: Point | None = None
    goal: Point | None = None
    last_seen_s: NonNegative | None = None
    distance_to_goal: NonNegative | None = None
    stale: bool = False
    deliberating: bool = False
    reason: Text = ""
    mission: Mission | None = None  # its full goal, x0 and parameters, once fixed
    phase: UnitPhase | None = None  # added with unit phases; null from an older planner


class ThreatSummary(_Message, frozen=True, kw_only=True):
    """One threat in force (``WorldSnapshot.threats``); ``ttl_s`` is the time left, null: no expiry."""

    id: Id
    threat: ThreatUpdate
    ttl_s: NonNegative | None = None


class TeamSummary(_Message, frozen=True, kw_only=True):
    """One team in force (``WorldSnapshot.teams``) and what its roles last said of its members.

    ``notes``: ``"unit: reason"`` for each member whose last direction a role held or redirected
    (``lost link: controller m1 has stopped``, ``waiting for m1: ...``).  ``eta_s``: the team's
    time to arrive, its slowest member's (``slowest``); null with ``slowest`` set: that member is
    lost or not moving; null with no ``slowest``: no member has a goal.
    """

    id: Id
    team: TeamUpdate
    notes: Annotated[list[Text], Meta(max_length=MAX_TEAM_MEMBERS)] = []
    eta_s: NonNegative | None = None
    slowest: Id | None = None


class WriteSummary(_Message, frozen=True, kw_only=True):
    """One record in force of a write kind listed by kind (``WorldSnapshot.writes``): a team, or a kind added later.

    ``kind`` is its kind's name (``team``), ``body`` its message as put (that kind's schema, a
    ``TeamUpdate`` for a team), ``ttl_s`` the time left (null: no expiry).  A joining planner
    decodes ``body`` with its kind's decoder, and skips a kind it does not know.
    """

    kind: Id
    id: Id
    body: dict[str, Any]
    ttl_s: NonNegative | None = None


class WorldSnapshot(_Message, frozen=True, kw_only=True):
    """Reply of ``mumt/{m}/planner/{p}/world``: one page of the zones, threats and units a planner holds.

    Lists are sorted by id, each capped at ``MAX_SNAPSHOT_ITEMS`` (or the query's
    limits) and all together at ``SNAPSHOT_PAGE_BYTES`` of JSON, zones first;
    ``zones_total``, ``threats_total`` and ``units_total`` say how many there are
    in all.  ``next_zone``, ``next_threat`` and ``next_unit`` are where the next
    page starts: ask again with
    ``?zones_from=<next_zone>;threats_from=<next_threat>;units_from=<next_unit>``
    (``WorldQuery``; a list already complete is left out with ``zones_limit=0``,
    ``threats_limit=0`` or ``units_limit=0``); null means that list is complete
    in this page, or was left out.  ``teams`` come whole on the first page only
    (as many as fit; ``teams_total`` counts them all), with what their roles said, for people.
    ``writes`` list the write kinds a planner learns by kind (teams, and any kind added later),
    by kind and id, after the threats; ``next_write`` (``kind.id``) is where the next page starts
    (``?writes_from=<next_write>``); ``writes_total`` counts them all.
    """

    planner: Id
    mission: Id
    units: Annotated[list[UnitSummary], Meta(max_length=MAX_SNAPSHOT_ITEMS)] = []
    threats: Annotated[list[ThreatSummary], Meta(max_length=MAX_SNAPSHOT_ITEMS)] = []
    units_total: Count = 0
    threats_total: Count = 0
    next_unit: Id | None = None
    next_threat: Id | None = None
    zones: Annotated[list[ZoneSummary], Meta(max_length=MAX_SNAPSHOT_ITEMS)] = []
    zones_total: Count = 0
    next_zone: Id | None = None
    teams: Annotated[list[TeamSummary], Meta(max_length=MAX_SNAPSHOT_ITEMS)] = []  # on the first page
    teams_total: Count = 0
    writes: Annotated[list[WriteSummary], Meta(max_length=MAX_SNAPSHOT_ITEMS)] = []
    writes_total: Count = 0  # added with writes; 0 from an older planner (its teams are in ``teams``)
    next_write: WriteCursor | None = None


class WorldQuery(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The parameters of a world query: which page (``…/world?units_from=ID;threats_from=ID;zones_from=ID;writes_from=KIND.ID``).

    Not a payload: Zenoh selector parameters, ``;``-separated, each at most
    once.  ``units_from``, ``threats_from``, ``zones_from`` and ``writes_from`` are the first ids
    the page lists (a reply's ``next_unit``, ``next_threat``, ``next_zone`` and ``next_write``);
    without one a list starts at its first id.  ``units_limit``,
    ``threats_limit``, ``zones_limit`` and ``writes_limit`` cap each list (0 to
    ``MAX_SNAPSHOT_ITEMS``; 0 leaves it out, for a list already complete).
    An unknown, repeated or malformed parameter is refused (``decode_world_query``).
    """

    units_from: Id | None = None
    threats_from: Id | None = None
    units_limit: Annotated[int, Meta(ge=0, le=MAX_SNAPSHOT_ITEMS)] = MAX_SNAPSHOT_ITEMS
    threats_limit: Annotated[int, Meta(ge=0, le=MAX_SNAPSHOT_ITEMS)] = MAX_SNAPSHOT_ITEMS
    zones_from: Id | None = None
    zones_limit: Annotated[int, Meta(ge=0, le=MAX_SNAPSHOT_ITEMS)] = MAX_SNAPSHOT_ITEMS
    writes_from: WriteCursor | None = None
    writes_limit: Annotated[int, Meta(ge=0, le=MAX_SNAPSHOT_ITEMS)] = MAX_SNAPSHOT_ITEMS

    def selector_parameters(self) -> str:
        """These parameters as a selector's ``?…`` part, without the ``?`` (empty: all defaults)."""
        default = WorldQuery()
        return ";".join(
            f"{name}={getattr(self, name)}"
            for name in self.__struct_fields__
            if getattr(self, name) != getattr(default, name)
        )
