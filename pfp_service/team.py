"""Team files and generated teams: which units there are, where they start and where they go.

A team file is YAML::

    name: demo-team
    units:
      - {id: u1, kind: manned, start: [0, 0], goal: [90, 80], speed_mps: 1.4}
      - {id: r1, kind: unmanned, start: [0, 10], goal: [95, 60], speed_mps: 3.0}
      - {id: r2, start: [0, 20], goal: [95, 40], speed_mps: 8, rate_hz: 2, gps_sigma_m: 3,
         stops: [{at_s: 10, for_s: 15}]}

``goal`` may be left out (the unit waits for one, e.g. from ``pfp inject``).
``mobility: {class: wheeled, max_slope_deg: 20}`` names the unit's mobility
class (``core.mobility.CLASSES``), and may override its ``height_m`` and
flat ``speed_mps`` as the wire does, which ``pfp fleet`` sends on every state
(the planner plans it round its class's slope barriers over terrain);
absent, ``pfp fleet --mobility``'s, else none (the planner's own class).
A unit never says a planner step: it drives at ``speed_mps`` and reports at
``rate_hz``, with its fix off by ``gps_sigma_m`` and its ``stops``, as a real
vehicle does (``core.tracking``).
``teams:`` group the units into teams with roles (``scenario.TeamSpec``, the
wire's ``TeamUpdate`` with an ``id``); every unit a team names must be one of
the file's, in one team only (but a lead may follow another team's lead), and
no cycle of leads::

    teams:
      - {id: alpha, lead: r1, follow: [m1, m2], standoff_m: 30, corridor_m: 6,
         controller: m1, robots: [r1, r2], radio_range_m: 80}

Keep-out ``zones:`` are the wire's zone form with an ``id``, as in scenario
files (``scenario.ZoneSpec``; vertices in metres, or ``{lat, lon}`` with an
``origin``); ``pfp fleet`` puts them before the goals::

    zones:
      - {id: minefield, polygon: [[[40, 5], [46, 5], [46, 35], [40, 35], [40, 5]]]}
      - {id: pond, circle: {centre: [20, 50], radius_m: 6}}
"""

from __future__ import annotations

import math
import random
from pathlib import Path
from typing import Annotated

import msgspec
from msgspec import Meta

from pfp_service.constraints import Id, Point
from pfp_service.core.mobility import CLASS_LIMITS, CLASSES, MobilityClass
from pfp_service.errors import InputError
from pfp_service.geo import Origin, localise_document
from pfp_service.scenario import TeamSpec, ZoneSpec, check_teams
from pfp_service.wire import GoalMobility, UnitKind
from pfp_service.wire.messages import TeamUpdate, ZoneUpdate, localise_zone
from pfp_service.wire.messages.structs import FlatSpeed, UnitHeight
from pfp_service.yamlio import load_yaml

__all__ = [
    "CHOICES",
    "SPEEDS_MPS",
    "MobilitySpec",
    "Stop",
    "Team",
    "UnitSpec",
    "generate_team",
    "load_team",
    "team_updates",
    "zone_updates",
]

Speed = Annotated[float, Meta(gt=0.0, le=1000.0)]
RateHz = Annotated[float, Meta(gt=0.0, le=50.0)]
SigmaM = Annotated[float, Meta(ge=0.0, le=100.0)]
Seconds = Annotated[float, Meta(ge=0.0, le=1e7)]
# a slope limit the planner plans at: none gentler than the gentlest class's (``core.mobility.planned_limit``)
PlannedSlope = Annotated[float, Meta(ge=CLASS_LIMITS[0], le=89.0)]
CHOICES: dict[str, tuple[str, ...]] = {"kind": tuple(k.value for k in UnitKind), "class": tuple(CLASSES)}
# Typical ground speeds used by generated teams: a soldier walking, a small robot driving.
SPEEDS_MPS: dict[UnitKind, tuple[float, float]] = {
    UnitKind.MANNED: (1.2, 1.6),
    UnitKind.UNMANNED: (2.0, 3.5),
}


class Stop(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A halt of a simulated vehicle: ``at_s`` simulated seconds into the run, for ``for_s`` seconds."""

    at_s: Seconds
    for_s: Annotated[float, Meta(gt=0.0, le=1e7)]


class MobilitySpec(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A unit's mobility class in a team file, as its states carry it (``wire.GoalMobility``)."""

    kind: MobilityClass = msgspec.field(name="class")
    max_slope_deg: PlannedSlope | None = None
    height_m: UnitHeight | None = None
    speed_mps: FlatSpeed | None = None

    def wire(self) -> GoalMobility:
        return GoalMobility(
            kind=self.kind, max_slope_deg=self.max_slope_deg, height_m=self.height_m, speed_mps=self.speed_mps
        )


class UnitSpec(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """One unit of a team: its id, kind, start, optional goal, ground speed, and how it behaves as a vehicle.

    ``rate_hz`` (its own report rate), ``stops`` and ``gps_sigma_m`` (the
    standard deviation of its reported fix, metres, per axis) default to the
    fleet's (``pfp fleet --rate-hz --stops --gps-sigma-m``).
    """

    id: Id
    kind: UnitKind = UnitKind.UNMANNED
    start: Point
    goal: Point | None = None
    speed_mps: Speed = 1.5
    rate_hz: RateHz | None = None
    stops: Annotated[list[Stop], Meta(max_length=1_000)] | None = None
    gps_sigma_m: SigmaM | None = None
    mobility: MobilitySpec | None = None


class Team(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A named list of units with distinct ids."""

    name: str = "team"
    origin: Origin | None = None  # where [0, 0] lies; positions may then be {lat, lon}
    units: Annotated[list[UnitSpec], Meta(min_length=1, max_length=10_000)]
    zones: Annotated[list[ZoneSpec], Meta(max_length=1_000)] = []  # keep-out zones, put by pfp fleet
    teams: Annotated[list[TeamSpec], Meta(max_length=1_000)] = []  # teams of these units, put by pfp fleet

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for i, u in enumerate(self.units):
            if u.id in seen:
                raise ValueError(f"units[{i}].id: duplicate id {u.id!r}")
            seen.add(u.id)
        zone_ids: set[str] = set()
        for i, (zid, _z) in enumerate(zone_updates(self)):
            if zid in zone_ids:
                raise ValueError(f"zones[{i}].id: duplicate id {zid!r}")
            zone_ids.add(zid)
        check_teams(self.teams, seen)


def zone_updates(team: Team) -> list[tuple[str, ZoneUpdate]]:
    """The team's zones as the wire puts them: ``(id, update)``, an id left out being ``zN``."""
    fields = ZoneUpdate.__struct_fields__
    return [
        (z.id or f"z{i + 1}", ZoneUpdate(**{f: getattr(z, f) for f in fields}))
        for i, z in enumerate(team.zones)
    ]


def team_updates(team: Team) -> list[tuple[str, TeamUpdate]]:
    """The file's teams as the wire puts them: ``(id, update)``."""
    fields = TeamUpdate.__struct_fields__
    return [(t.id, TeamUpdate(**{f: getattr(t, f) for f in fields})) for t in team.teams]


def _localise_zones(doc: dict[str, object]) -> dict[str, object]:
    """A team file's zone vertices given as ``{lat, lon}`` in metres from its origin (``load_yaml``'s hook)."""
    zones = doc.get("zones")
    if not isinstance(zones, list):
        return doc
    origin = localise_document({"origin": doc["origin"]}).get("origin") if "origin" in doc else None
    at = msgspec.convert(origin, Origin) if origin is not None else None
    return {**doc, "zones": [localise_zone(z, at, f"zones[{i}]") for i, z in enumerate(zones)]}


def load_team(path: str | Path) -> Team:
    """Read a team file.

    Raises:
        InputError: naming the file, the line and the field.
    """
    team, _root = load_yaml(path, Team, CHOICES, prepare=_localise_zones)
    return team


def generate_team(n: int, seed: int, area_m: float, manned_share: float = 0.5) -> Team:
    """``n`` units with seeded random starts on the west edge and goals on the east edge of a square.

    Args:
        n: how many units (>= 1).
        seed: seeds the generator; the same seed gives the same team.
        area_m: side of the square ``[0, area_m]^2`` in metres.
        manned_share: fraction of manned units (the rest unmanned).
    """
    if n < 1:
        raise InputError("--generate", "must be >= 1")
    if not (math.isfinite(area_m) and area_m > 0):
        raise InputError("--area", "must be a finite number > 0")
    rng = random.Random(seed)
    n_manned = round(n * manned_share)
    units = []
    for i in range(n):
        kind = UnitKind.MANNED if i < n_manned else UnitKind.UNMANNED
        lo, hi = SPEEDS_MPS[kind]
        prefix = "m" if kind is UnitKind.MANNED else "r"
        units.append(
            UnitSpec(
                id=f"{prefix}{i + 1}",
                kind=kind,
                start=(rng.uniform(0.0, 0.1) * area_m, rng.uniform(0.05, 0.95) * area_m),
                goal=(rng.uniform(0.9, 1.0) * area_m, rng.uniform(0.05, 0.95) * area_m),
                speed_mps=round(rng.uniform(lo, hi), 2),
            )
        )
    return Team(name=f"generated-{n}-seed{seed}", units=units)
