"""Injection scripts: a timeline of contingencies and the expectations that judge the planner.

A script is YAML, validated whole before anything is sent::

    name: figure-8
    duration_s: 120            # simulated seconds at most
    timeline:                  # run in order; each entry waits for its trigger
      - {do: add_threat, threat: e1, position: [4, 6], facing_deg: 225,
         sigma_range: 1.0, sigma_lateral: 0.7, skew: 2}
      - {do: set_goal, unit: u1, position: [10, 10]}
      - {do: add_threat, when: {unit: u1, within_m: 0.5, of: [4.6, 4.9]},
         threat: e3, position: [6, 7], facing_deg: 225, sigma_range: 1.0, sigma_lateral: 0.7}
      - {do: wait, seconds: 5}
      - {do: move_threat, threat: e3, position: [6, 8]}
      - {do: add_zone, zone: z1, circle: {centre: [8, 3], radius_m: 1.0}}
      - {do: add_zone, zone: z2, polygon: [[[1, 7], [2, 7], [2, 9], [1, 9], [1, 7]]]}
      - {do: remove_zone, zone: z2, at_s: 40}
    expect:
      - {unit: u1, arrives_within_s: 60}
      - {unit: u1, min_clearance_m: 1.5, to: e3}
      - {unit: u1, never_enters: z1}

Triggers: none (right after the previous entry), ``at_s`` (seconds from the
start; at once if already past) or ``when`` (a unit within ``within_m`` of a
point).  Actions: ``add_threat``, ``move_threat``, ``remove_threat``,
``add_zone`` (the wire's zone: ``polygon`` rings or a ``circle``, vertices
``[x, y]`` or ``{lat, lon}``, optional ``ttl_s``; put again to move it),
``remove_zone``, ``add_team`` (the wire's team, its fields beside ``team:``,
its id: put again to change it, ``goal`` included), ``remove_team``,
``set_goal``, ``cancel_goal``, ``wait``.  Expectations:
``arrives_within_s``, ``min_clearance_m`` (to one threat or all),
``never_enters`` (a zone: no segment of the unit's track while the zone was in
force touches it, checked exactly per segment by ``core.zones.track_enters``),
and a team's: ``{unit, keeps_from: other, at_least_m}``, ``{unit,
only_cleared_by: lead, corridor_m}`` and ``{unit, link_to: controller,
at_least_pct, radio_range_m}`` (``team_expectations``), and ``{team,
arrives_within_s}`` (every member of a team the timeline adds arrives in time).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Union

import msgspec
from msgspec import Meta

from pfp_service.constraints import Id, NonNegative, Point, Positive, Sigma, Skew, Weight
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import Goal, ThreatUpdate
from pfp_service.wire.messages import TeamUpdate, ZoneUpdate, localise_zone
from pfp_service.wire.messages.structs import (
    DEFAULT_SHAPE,
    MAX_ZONE_RINGS,
    Ring,
    ShapeName,
    ShapeParams,
    ZoneCircle,
    ZoneKind,
)
from pfp_service.wire.messages.teams import Distance, Ids, Offsets
from pfp_service.world import translate
from pfp_service.yamlio import load_yaml, located

__all__ = [
    "ACTIONS",
    "AddTeam",
    "AddThreat",
    "AddZone",
    "CancelGoal",
    "Expect",
    "MoveThreat",
    "RemoveTeam",
    "RemoveThreat",
    "RemoveZone",
    "Script",
    "SetGoal",
    "Step",
    "Wait",
    "When",
    "load_script",
    "team_members",
]

Angle = Annotated[float, Meta(ge=-360.0, le=360.0)]
ACTIONS = (
    "add_threat",
    "move_threat",
    "remove_threat",
    "add_zone",
    "remove_zone",
    "add_team",
    "remove_team",
    "set_goal",
    "cancel_goal",
    "wait",
)


class When(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Fires once ``unit`` is reported within ``within_m`` metres of ``of``."""

    unit: Id
    within_m: Positive
    of: Point


Show = Callable[[tuple[float, float]], str] | None  # how a position is written (coords.Coords.point)


def _shown(p: tuple[float, float], show: Show) -> str:
    return show(p) if show is not None else f"({p[0]:g}, {p[1]:g})"


class _Step(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True, tag_field="do"):
    at_s: NonNegative | None = None
    when: When | None = None

    def __post_init__(self) -> None:
        if self.at_s is not None and self.when is not None:
            raise ValueError("when: give at_s or when, not both")

    def describe(self, show: Show = None) -> str:
        """The entry in words; ``show`` writes a position (``coords.Coords.point``), else ``(x, y)`` metres."""
        raise NotImplementedError


class AddThreat(_Step, kw_only=True, frozen=True, tag="add_threat"):
    """Put a new threat (or replace one) with its full shape."""

    threat: Id
    position: Point
    shape: ShapeName = DEFAULT_SHAPE
    facing_deg: Angle = 0.0
    sigma_range: Sigma | None = None
    sigma_lateral: Sigma | None = None
    skew: Skew = 0.0
    params: ShapeParams | None = None
    weight: Weight = 1.0
    ttl_s: Positive | None = None

    def __post_init__(self) -> None:
        translate.check(self.update())  # the message's own checks, then its shape's

    def update(self) -> ThreatUpdate:
        return ThreatUpdate(
            position=self.position,
            shape=self.shape,
            facing_deg=self.facing_deg,
            sigma_range=self.sigma_range,
            sigma_lateral=self.sigma_lateral,
            skew=self.skew,
            params=self.params,
            weight=self.weight,
            ttl_s=self.ttl_s,
        )

    def describe(self, show: Show = None) -> str:
        return f"add threat {self.threat} at {_shown(self.position, show)}"


class MoveThreat(_Step, kw_only=True, frozen=True, tag="move_threat"):
    """Move a threat the script added (its shape is kept; the facing may change)."""

    threat: Id
    position: Point
    facing_deg: Angle | None = None

    def describe(self, show: Show = None) -> str:
        return f"move threat {self.threat} to {_shown(self.position, show)}"


class RemoveThreat(_Step, kw_only=True, frozen=True, tag="remove_threat"):
    """Delete a threat."""

    threat: Id

    def describe(self, show: Show = None) -> str:
        return f"remove threat {self.threat}"


class AddZone(_Step, kw_only=True, frozen=True, tag="add_zone"):
    """Put a keep-out zone (or replace one: a zone is moved by putting it again), as the wire's ``ZoneUpdate``."""

    zone: Id
    kind: ZoneKind = "keep_out"
    polygon: Annotated[list[Ring], Meta(min_length=1, max_length=MAX_ZONE_RINGS)] | None = None
    circle: ZoneCircle | None = None
    ttl_s: Positive | None = None

    def __post_init__(self) -> None:
        self.update()  # the wire's own checks: one shape, closed simple rings, bounds

    def update(self) -> ZoneUpdate:
        return ZoneUpdate(kind=self.kind, polygon=self.polygon, circle=self.circle, ttl_s=self.ttl_s)

    def describe(self, show: Show = None) -> str:
        if self.circle is not None:
            c = self.circle
            return f"add zone {self.zone}: a circle of {c.radius_m:g} m round {_shown(c.centre, show)}"
        assert self.polygon is not None
        return f"add zone {self.zone}: a polygon of {len(self.polygon[0]) - 1} vertices from {_shown(self.polygon[0][0], show)}"


class RemoveZone(_Step, kw_only=True, frozen=True, tag="remove_zone"):
    """Delete a keep-out zone."""

    zone: Id

    def describe(self, show: Show = None) -> str:
        return f"remove zone {self.zone}"


class AddTeam(_Step, kw_only=True, frozen=True, tag="add_team"):
    """Put a team (or change one: put it again), as the wire's ``TeamUpdate`` (docs/teams.md)."""

    team: Id
    members: Ids = []
    separation_m: Distance | None = None
    lead: Id | None = None
    follow: Ids = []
    standoff_m: Distance = 300.0
    corridor_m: Distance = 30.0
    controller: Id | None = None
    robots: Ids = []
    radio_range_m: Distance = 1500.0
    goal: Goal | None = None
    offsets: Offsets = {}
    spacing_m: Distance | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        self.update()  # the wire's own checks: roles, lists, offsets

    def update(self) -> TeamUpdate:
        return TeamUpdate(**{f: getattr(self, f) for f in TeamUpdate.__struct_fields__})

    def describe(self, show: Show = None) -> str:
        units = self.update().units()
        goal = f", its goal {_shown(self.goal.position, show)}" if self.goal is not None else ""
        return f"add team {self.team}: {' '.join(units)}{goal}"


class RemoveTeam(_Step, kw_only=True, frozen=True, tag="remove_team"):
    """Dissolve a team."""

    team: Id

    def describe(self, show: Show = None) -> str:
        return f"remove team {self.team}"


class SetGoal(_Step, kw_only=True, frozen=True, tag="set_goal"):
    """Give a unit a goal; ``step``/``tolerance``/``delta`` as in the wire ``Goal``."""

    unit: Id
    position: Point
    step: Positive | None = None
    tolerance: Positive | None = None
    delta: Positive | None = None

    def goal(self) -> Goal:
        return Goal(position=self.position, step=self.step, tolerance=self.tolerance, delta=self.delta)

    def describe(self, show: Show = None) -> str:
        return f"set goal of {self.unit} to {_shown(self.position, show)}"


class CancelGoal(_Step, kw_only=True, frozen=True, tag="cancel_goal"):
    """Cancel a unit's goal."""

    unit: Id

    def describe(self, show: Show = None) -> str:
        return f"cancel goal of {self.unit}"


class Wait(_Step, kw_only=True, frozen=True, tag="wait"):
    """Hold the timeline for ``seconds`` (simulated)."""

    seconds: Positive

    def describe(self, show: Show = None) -> str:
        return f"wait {self.seconds:g} s"


Step = Union[  # noqa: UP007
    AddThreat, MoveThreat, RemoveThreat, AddZone, RemoveZone, AddTeam, RemoveTeam, SetGoal, CancelGoal, Wait
]


class Expect(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """One expectation of ``unit``: exactly one of ``arrives_within_s``, ``min_clearance_m`` (to threat ``to``,
    else to all), ``never_enters``, or a team's (``keeps_from``, ``only_cleared_by``, ``link_to``).
    Or of ``team`` (in place of ``unit``), with ``arrives_within_s``: every member arrives in time.

    ``keeps_from: other`` with ``at_least_m``: the unit never comes closer to ``other``.
    ``only_cleared_by: lead`` (with the team's ``corridor_m``): once in the lead's corridor, the unit is never
    outside ground the lead crossed before it.  ``link_to: controller`` with ``at_least_pct`` (and the team's
    ``radio_range_m``): the share of the unit's reports within radio range of its controller.
    """

    unit: Id | None = None
    team: Id | None = None
    arrives_within_s: Positive | None = None
    min_clearance_m: NonNegative | None = None
    to: Id | None = None
    never_enters: Id | None = None
    keeps_from: Id | None = None
    at_least_m: NonNegative | None = None
    only_cleared_by: Id | None = None
    corridor_m: Positive = 30.0
    link_to: Id | None = None
    at_least_pct: Annotated[float, Meta(ge=0.0, le=100.0)] | None = None
    radio_range_m: Positive = 1500.0

    @property
    def who(self) -> str:
        """The unit judged, or ``team X``."""
        return self.unit if self.unit is not None else f"team {self.team}"

    def __post_init__(self) -> None:
        if (self.unit is None) == (self.team is None):
            raise ValueError("unit: give a unit, or a team (with arrives_within_s)")
        if self.team is not None and self.arrives_within_s is None:
            raise ValueError("team: a team's expectation is arrives_within_s")
        kinds = (self.arrives_within_s, self.min_clearance_m, self.never_enters, self.keeps_from)
        given = [x is not None for x in (*kinds, self.only_cleared_by, self.link_to)]
        if sum(given) != 1:
            raise ValueError(
                "arrives_within_s: give exactly one of arrives_within_s, min_clearance_m, never_enters, "
                "keeps_from, only_cleared_by or link_to"
            )
        if self.to is not None and self.min_clearance_m is None:
            raise ValueError("to: only goes with min_clearance_m")
        if (self.keeps_from is None) != (self.at_least_m is None):
            raise ValueError("at_least_m: keeps_from and at_least_m go together")
        if (self.link_to is None) != (self.at_least_pct is None):
            raise ValueError("at_least_pct: link_to and at_least_pct go together")

    def describe(self) -> str:
        if self.arrives_within_s is not None:
            return f"{self.who} arrives within {self.arrives_within_s:g} s"
        if self.never_enters is not None:
            return f"{self.unit} never enters zone {self.never_enters}"
        if self.keeps_from is not None:
            return f"{self.unit} keeps at least {self.at_least_m:g} m from {self.keeps_from}"
        if self.only_cleared_by is not None:
            return (
                f"{self.unit} enters only ground {self.only_cleared_by} cleared ({self.corridor_m:g} m wide)"
            )
        if self.link_to is not None:
            return (
                f"{self.unit} within {self.radio_range_m:g} m of {self.link_to} "
                f">= {self.at_least_pct:g} % of the time"
            )
        return f"min clearance of {self.unit} to {self.to or 'every threat'} >= {self.min_clearance_m:g} m"


class Script(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A whole injection script."""

    name: str = "script"
    origin: Origin | None = None  # where [0, 0] lies; positions may then be {lat, lon}
    duration_s: Positive = 300.0
    timeline: Annotated[list[Step], Meta(max_length=10_000)] = []
    expect: Annotated[list[Expect], Meta(max_length=10_000)] = []


def _check_references(script: Script) -> None:
    """Threats moved, removed or named by an expectation must be added by the script first."""
    added: set[str] = set()
    for i, step in enumerate(script.timeline):
        if isinstance(step, AddThreat):
            added.add(step.threat)
        elif isinstance(step, (MoveThreat, RemoveThreat)) and step.threat not in added:
            raise InputError(f"timeline[{i}].threat", f"{step.threat!r} is not added earlier in the timeline")
        if isinstance(step, RemoveThreat):
            added.discard(step.threat)
    zones: set[str] = set()
    for i, step in enumerate(script.timeline):
        if isinstance(step, AddZone):
            zones.add(step.zone)
        elif isinstance(step, RemoveZone):
            if step.zone not in zones:
                raise InputError(f"timeline[{i}].zone", f"{step.zone!r} is not added earlier in the timeline")
            zones.discard(step.zone)
    teams = {s.team for s in script.timeline if isinstance(s, AddTeam)}
    for i, e in enumerate(script.expect):
        if e.team is not None and e.team not in teams:
            raise InputError(f"expect[{i}].team", f"team {e.team!r} is never added by the timeline")
    ever = {s.threat for s in script.timeline if isinstance(s, AddThreat)}
    ever_zones = {s.zone for s in script.timeline if isinstance(s, AddZone)}
    for i, e in enumerate(script.expect):
        if e.to is not None and e.to not in ever:
            raise InputError(f"expect[{i}].to", f"{e.to!r} is never added by the timeline")
        if e.never_enters is not None and e.never_enters not in ever_zones:
            raise InputError(
                f"expect[{i}].never_enters", f"zone {e.never_enters!r} is never added by the timeline"
            )


def load_script(path: str | Path) -> Script:
    """Read and validate a script: types, bounds, triggers and references to threats.

    Raises:
        InputError: naming the file, the line and the field.
    """
    p = Path(path)
    script, root = load_yaml(p, Script, {"do": ACTIONS}, prepare=_localise_zones)
    try:
        _check_references(script)
    except InputError as err:
        raise located(p, root, err) from None
    return script


def _localise_zones(doc: dict[str, object]) -> dict[str, object]:
    """``add_zone`` vertices and centres given as ``{lat, lon}`` in metres from the script's origin.

    Raises:
        InputError: a bad lat/lon, or one without an origin, at ``timeline[i].polygon[j][k]``.
    """
    timeline = doc.get("timeline")
    if not isinstance(timeline, list) or not any(
        isinstance(e, dict) and e.get("do") == "add_zone" for e in timeline
    ):
        return doc
    raw = doc.get("origin")
    origin = None
    if isinstance(raw, dict):
        try:
            origin = msgspec.convert(raw, Origin)
        except msgspec.ValidationError:
            origin = None  # the Script's own validation names the origin's fault
    steps = [
        localise_zone(e, origin, f"timeline[{i}]") if isinstance(e, dict) and e.get("do") == "add_zone" else e
        for i, e in enumerate(timeline)
    ]
    return {**doc, "timeline": steps}


def team_members(script: Script) -> dict[str, tuple[str, ...]]:
    """Each team the timeline adds and its members, as last put."""
    return {s.team: s.update().units() for s in script.timeline if isinstance(s, AddTeam)}
