"""The planner's events, on ``mumt/{m}/event/{kind}``: a tagged union whose ``kind`` repeats the key's last chunk.

Apart from the other Structs (``structs``) because they are one family with one decoder
(``codec.decode_event``) and grow together; their common field types come from ``structs``.
"""

from __future__ import annotations

from typing import Annotated, Any, Union

from msgspec import Meta

from pfp_service.constraints import Id, NonNegative, Point
from pfp_service.errors import InputError
from pfp_service.wire.messages.structs import (
    MAX_EVENT_ITEMS,
    Count,
    Text,
    Time,
    _Message,
    fit_text,
)

__all__ = [
    "EVENT_KINDS",
    "AnyEvent",
    "ArrivedEvent",
    "ConflictEvent",
    "DeadlockEvent",
    "Event",
    "ForgottenEvent",
    "RejectedEvent",
    "ReplanEvent",
    "RestoredEvent",
    "StaleEvent",
    "ThreatChange",
    "TrappedEvent",
]


# -- events on mumt/{m}/event/{kind}; "kind" repeats the key's last chunk -------
class Event(_Message, frozen=True, kw_only=True, tag_field="kind"):
    """Base of planner events.  ``t`` is the planner's Unix time in seconds."""

    planner: Id | None = None
    t: Time | None = None


class RejectedEvent(Event, frozen=True, kw_only=True, tag="rejected"):
    """An input the planner refused: the key it came on, the field path and why."""

    key: Text
    field: Text = "$"
    reason: Text
    suppressed: Count = 0  # rejections of the same kind of key not sent since the last one
    truncated: bool = False  # key, field or reason was cut to TEXT_MAX_CHARS (it then ends in "…")

    @classmethod
    def of(
        cls, key: str, exc: InputError, planner: str | None = None, t: float | None = None
    ) -> RejectedEvent:
        """The event for ``exc`` on ``key``, every text cut to fit the schema and marked ``truncated``."""
        texts = (str(key), exc.path or "$", exc.reason)
        k, f, r = (fit_text(s) for s in texts)
        return cls(key=k, field=f, reason=r, truncated=(k, f, r) != texts, planner=planner, t=t)


class ThreatChange(_Message, frozen=True, kw_only=True):
    """One change to the threats in force: ``put``, ``removed`` or ``expired``."""

    threat: Id
    change: Annotated[str, Meta(pattern="^(put|removed|expired)$")]
    position: Point | None = None


class ReplanEvent(Event, frozen=True, kw_only=True, tag="replan"):
    """The threats changed, and these units got fresh directions.

    ``changes`` lists what changed (at most ``MAX_EVENT_ITEMS``; ``more`` counts
    the rest), ``units`` the units re-directed (also capped, ``more_units``).
    """

    units: Annotated[list[Id], Meta(max_length=MAX_EVENT_ITEMS)]
    reason: Text
    changes: Annotated[list[ThreatChange], Meta(max_length=MAX_EVENT_ITEMS)] = []
    more: Count = 0
    more_units: Count = 0


class StaleEvent(Event, frozen=True, kw_only=True, tag="stale"):
    """A unit went silent (or its liveliness token went) and gets no directions until it reports."""

    unit: Id
    position: Point
    reason: Text = ""


class ForgottenEvent(Event, frozen=True, kw_only=True, tag="forgotten"):
    """A unit stale for ``unit_forget_s`` was dropped, with its goal and memory."""

    unit: Id
    stale_s: NonNegative = 0.0


class TrappedEvent(Event, frozen=True, kw_only=True, tag="trapped"):
    """A unit is honestly stuck."""

    unit: Id
    position: Point
    reason: Text = ""


class ArrivedEvent(Event, frozen=True, kw_only=True, tag="arrived"):
    """A unit is within tolerance of its goal."""

    unit: Id
    position: Point
    distance_to_goal: NonNegative = 0.0


class RestoredEvent(Event, frozen=True, kw_only=True, tag="restored"):
    """A planner started from its durable state: how much it found.

    ``kinds``: the count restored of every kind of write it keeps, by the kind's name (``goal``,
    ``threat``, ``zone``, ``team``, and any kind added later); ``threats``, ``goals``, ``zones`` and
    ``teams`` repeat the first four for readers older than ``kinds`` (``counted`` fills both).
    """

    threats: Count = 0
    goals: Count = 0
    missions: Count = 0
    expired: Count = 0  # threats and zones whose TTL ran out while the planner was down
    zones: Count = 0  # keep-out zones restored
    corrupt: Count = 0  # rows skipped as unreadable, plus the damaged pages of a state file set aside
    set_aside: Text = ""  # where a damaged state file was moved (kept), if one was
    teams: Count = 0  # teams restored
    kinds: Annotated[dict[Id, Count], Meta(max_length=64)] = {}  # added with it; {} from an older planner

    @classmethod
    def counted(cls, kinds: dict[str, int], **rest: Any) -> RestoredEvent:
        """The event for ``kinds`` (restored, by kind name), its named counts filled from it."""
        # the counts named one by one before ``kinds``, kept for older readers; a kind added since
        # is counted in ``kinds`` only (schemas only grow: these stay as they are)
        got = kinds.get
        threats, goals, zones, teams = got("threat", 0), got("goal", 0), got("zone", 0), got("team", 0)
        return cls(kinds=kinds, threats=threats, goals=goals, zones=zones, teams=teams, **rest)


class ConflictEvent(Event, frozen=True, kw_only=True, tag="conflict"):
    """Another planner serves the same mission, and scale-out is not configured: both answer every unit."""

    other: Id
    reason: Text = ""


class DeadlockEvent(Event, frozen=True, kw_only=True, tag="deadlock"):
    """Dispersion found a deadlock: ``unit`` and ``other`` held, or stood still, this long.

    ``unit`` resolves it (``yielding``) for at most ``backoff_s``: it backs off
    from ``other``, or goes round it when ``other`` is at rest, and then goes
    on as any unit does; ``reason`` says so in words.
    """

    unit: Id
    other: Id
    position: Point
    held_s: NonNegative = 0.0
    backoff_s: NonNegative = 0.0
    reason: Text = ""


AnyEvent = Union[  # noqa: UP007
    RejectedEvent,
    ReplanEvent,
    TrappedEvent,
    ArrivedEvent,
    StaleEvent,
    ForgottenEvent,
    RestoredEvent,
    ConflictEvent,
    DeadlockEvent,
]
EVENT_KINDS: tuple[str, ...] = (
    "rejected",
    "replan",
    "trapped",
    "arrived",
    "stale",
    "forgotten",
    "restored",
    "conflict",
    "deadlock",
)
