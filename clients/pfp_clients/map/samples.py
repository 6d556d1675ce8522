"""The map's inputs: one frozen record per kind of sample the Zenoh callbacks decode (``feed``).

``MapModel.apply`` (``model``) takes a batch of them; kept apart so the feed and the model
share the inputs' definitions and nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass

from pfp_service.wire import Direction, Event, Goal, PlannerStatus, ThreatUpdate, UnitState, WorldSnapshot
from pfp_service.wire.messages import TeamUpdate, ZoneUpdate

__all__ = [
    "AliveSeen",
    "DirectionSeen",
    "EventSeen",
    "GoalSeen",
    "Input",
    "StateSeen",
    "StatusSeen",
    "TeamSeen",
    "ThreatSeen",
    "WorldSeen",
    "ZoneSeen",
]


# -- inputs: one frozen record per kind of sample --------------------------------
@dataclass(frozen=True, slots=True)
class StateSeen:
    unit: str
    state: UnitState


@dataclass(frozen=True, slots=True)
class DirectionSeen:
    unit: str
    direction: Direction


@dataclass(frozen=True, slots=True)
class GoalSeen:
    """A goal put, or cancelled (``goal`` is None)."""

    unit: str
    goal: Goal | None


@dataclass(frozen=True, slots=True)
class ThreatSeen:
    """A threat put, or removed (``update`` is None)."""

    threat: str
    update: ThreatUpdate | None


@dataclass(frozen=True, slots=True)
class ZoneSeen:
    """A keep-out zone put, or removed (``update`` is None)."""

    zone: str
    update: ZoneUpdate | None


@dataclass(frozen=True, slots=True)
class TeamSeen:
    """A team put, or dissolved (``update`` is None)."""

    team: str
    update: TeamUpdate | None


@dataclass(frozen=True, slots=True)
class AliveSeen:
    unit: str
    alive: bool


@dataclass(frozen=True, slots=True)
class EventSeen:
    event: Event


@dataclass(frozen=True, slots=True)
class StatusSeen:
    status: PlannerStatus


@dataclass(frozen=True, slots=True)
class WorldSeen:
    """A planner's reply to the world query: what it held before the map started listening."""

    world: WorldSnapshot


Input = (
    StateSeen
    | DirectionSeen
    | GoalSeen
    | ThreatSeen
    | ZoneSeen
    | TeamSeen
    | AliveSeen
    | EventSeen
    | StatusSeen
    | WorldSeen
)
