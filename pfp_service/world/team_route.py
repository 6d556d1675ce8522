"""A lead's route priced for its followers: the ground it plans over is ground they can take after it.

A follower enters only ground its lead has crossed, ``corridor_m`` wide (``teams.follow``).  A lead
that plans for itself alone may choose a gap it fits through and the corridor does not, or a slope
it climbs and its followers cannot: they stop at the end of the corridor.  The lead scouts along the
main element's route (``teams.lead``) and goes its own way for the last standoff, so every unit in
a column (a team's lead and its followers) plans under one key (``RouteKeys``): the strictest slope
limit of the column (``world.mobility``), and every zone and barrier grown by half the widest
corridor (``widened``), so that the whole corridor round the track stays clear of them.  A zone
grown over a unit's goal keeps its own shape, and a unit whose goal lies past the column's slope
limit plans at its own.  The key ends with the unit's own height over terrain (``world.mobility.height_of``;
``None``, the planner's class's): a threat sees each unit at its own, whatever its column.  The key picks the field (``Records.field_for``); the live steering, a
mission's start, deliberation and a unit's preview (``World.view``) all take it from there, so a
preview shows the route the unit takes.  Pure: records and teams in, a key out.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

import shapely

from pfp_service.core.mobility import planned_limit
from pfp_service.core.zones import MAX_VERTICES, Zone, ZoneSet
from pfp_service.world.mobility import height_of, limit_of

if TYPE_CHECKING:
    from pfp_service.world.team_book import TeamBook
    from pfp_service.world.terrain import Ground
    from pfp_service.world.units import UnitRecord

__all__ = ["RouteKey", "RouteKeys", "groups", "widened"]

# (slope limit, zones grown by, ids of zones left as they are, height seen at): what picks a unit's field
RouteKey = tuple[int | None, float, tuple[str, ...], float | None]
PLAIN: RouteKey = (None, 0.0, (), None)
_SIMPLIFY_SHARE = 0.1  # of the margin: how far a grown outline too detailed for a zone may be simplified


def widened(zone: Zone, margin_m: float) -> Zone:
    """``zone`` grown by at least ``margin_m`` all round (a circle exactly; a polygon's mitred outline
    contains the round one), under the same id."""
    if zone.centre is not None:
        return Zone.circle(zone.id, zone.centre, zone.radius_m + margin_m, zone.kind)
    grown = shapely.buffer(zone.geometry, margin_m, join_style="mitre", mitre_limit=4.0)
    if shapely.get_num_coordinates(grown) > MAX_VERTICES:  # simplified within a tenth, then grown by it
        tol = _SIMPLIFY_SHARE * margin_m
        grown = shapely.buffer(shapely.simplify(grown, tol), tol, join_style="mitre", mitre_limit=4.0)
    if not isinstance(grown, shapely.Polygon):  # a polygon grown is one polygon; keep the safe original else
        return zone
    shell = tuple(grown.exterior.coords)[:-1]
    holes = tuple(tuple(r.coords)[:-1] for r in grown.interiors)
    try:
        return Zone(id=zone.id, shell=shell, holes=holes, kind=zone.kind)
    except ValueError:
        return zone  # an outline GEOS made that the zone's checks refuse: the zone as it is


def grown_set(zones: ZoneSet, margin_m: float) -> ZoneSet:
    """Every zone of ``zones`` grown by ``margin_m`` (``widened``)."""
    return ZoneSet(widened(z, margin_m) for z in zones)


def kept_for(grown: ZoneSet, plain: ZoneSet, goal: tuple[float, float]) -> tuple[str, ...]:
    """The ids of the grown zones that cover ``goal`` (each keeps its own shape), in id order."""
    keep: list[str] = []
    here = grown.zone_at(*goal)
    while here and here not in keep:
        keep.append(here)
        original = plain.get(here)
        grown = grown.plus([original] if original is not None else [], [here])
        here = grown.zone_at(*goal)
    return tuple(sorted(keep))


class _Records(Protocol):
    """What a key needs of the world's records (``world_records.Records``, which builds on this module)."""

    units: dict[str, UnitRecord]

    def zone_set_for(
        self, slope: int | None, margin_m: float = 0.0, keep: tuple[str, ...] = ()
    ) -> ZoneSet: ...


class RouteKeys:
    """Each unit's ``RouteKey``: its own slope limit, or, leading followers, theirs and the corridor's margin;
    and its own height."""

    def __init__(self, records: _Records, teams: TeamBook, ground: Ground | None) -> None:
        self._rec, self._teams = records, teams
        unit = getattr(ground, "unit", None)  # the planner's class: a goal naming none plans as it
        self._planner = planned_limit(unit.max_slope_deg) if unit is not None else None
        self._height = unit.height_m if unit is not None else None
        self._terrain = ground is not None

    def height(self, rec: UnitRecord) -> float | None:
        """The height a threat sees ``rec`` at: its class's, ``None`` when that is the planner's class's
        (or without terrain), so that every unit of one height shares one field."""
        if not self._terrain or (rec.mobility is None and (rec.goal is None or rec.goal.mobility is None)):
            return None  # no class named (every tick's common case, asked per unit): the planner's
        own = height_of(rec)
        return None if own is None or own == self._height else own

    def groups(
        self, guided: list[Any], owed: list[tuple[Any, Any]]
    ) -> dict[RouteKey, tuple[list[Any], list[Any]]]:
        """``groups`` by these keys.  With no terrain and no team every key is ``PLAIN``, so none is asked
        unit by unit (a micro-optimisation, ~1 us a unit: BENCHMARKS.md, issue 31)."""
        if not self._terrain and not self._teams.teams:
            return {PLAIN: (guided, owed)} if guided or owed else {}
        return groups(guided, owed, self)

    def __call__(self, rec: UnitRecord | None) -> RouteKey:
        if rec is None:
            return PLAIN
        own = limit_of(rec) if self._terrain else None
        tall = self.height(rec)
        led = self._teams.columns(rec.id)
        if not led:
            return (own, 0.0, (), tall)
        units: Mapping[str, UnitRecord] = self._rec.units
        slope = own
        if self._terrain and self._planner is not None:  # the strictest limit of the lead and its followers
            mine = self._planner if own is None else own
            column = {u for t in led for u in (t.lead, *t.follow) if u is not None and u != rec.id}
            theirs = [limit_of(r) for u in sorted(column) if (r := units.get(u)) is not None]
            strictest = min([mine, *(self._planner if lim is None else lim for lim in theirs)])
            slope = own if strictest == mine else strictest
            if (
                slope != own
                and rec.goal is not None
                and self._rec.zone_set_for(slope).zone_at(*rec.goal.position)
            ):
                slope = own  # its goal lies past the others' limit: it goes there on its own
        margin = max(t.corridor_m for t in led) / 2.0
        if margin <= 0.0 or not math.isfinite(margin) or not self._rec.zone_set_for(slope):
            return (
                slope,
                0.0,
                (),
                tall,
            )  # nothing to keep the corridor clear of: the field of the unit's class
        keep = (
            kept_for(self._rec.zone_set_for(slope, margin), self._rec.zone_set_for(slope), rec.goal.position)
            if rec.goal is not None
            else ()
        )
        return (slope, margin, keep, tall)


def groups(
    guided: list[Any], owed: list[tuple[Any, Any]], key_of: Callable[[Any], RouteKey]
) -> dict[RouteKey, tuple[list[Any], list[Any]]]:
    """The units to steer (records) and those owed their points (``(record, advice)``) by their route key,
    each in the order given: each group is steered under its own field (``Records.field_for``)."""
    out: dict[RouteKey, tuple[list[Any], list[Any]]] = {}
    for rec in guided:
        out.setdefault(key_of(rec), ([], []))[0].append(rec)
    for item in owed:
        out.setdefault(key_of(item[0]), ([], []))[1].append(item)
    return out
