"""The world's records: one per unit, threat and keep-out zone, and the counts kept with them.

A unit's record and its one writer are ``units`` (``Records.book``: its
phase, and every write that decides it); the records here are the threats'
and zones': a threat or a zone is put, removed or expires.  The field in
force carries the zones in force (``ThreatField.with_zones``, as
``core.zones`` says): whatever takes the field -- the stepper, deliberation
jobs, previews -- sees them.  They return what changed; the world decides
what goes out.  Pure values: ``now`` is a parameter.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pfp_service.core import Threat, ThreatField
from pfp_service.core.cull import MIN_THREATS, CullIndex
from pfp_service.core.params import FieldStats, field_stats
from pfp_service.core.visibility import Window, reach_box
from pfp_service.core.zones import Zone, ZoneSet
from pfp_service.wire import Mission, ThreatUpdate
from pfp_service.wire.messages import ZoneUpdate
from pfp_service.world import team_route
from pfp_service.world.mobility import limit_of
from pfp_service.world.slopes import SLOPE_SETS, Slopes
from pfp_service.world.team_route import RouteKey
from pfp_service.world.terrain import Ground, Looks, SightAsk, SightKey, ground_zones, sight_key
from pfp_service.world.units import UnitRecord, Units

__all__ = ["MAX_HEIGHTS", "MAX_SLOPE_SETS", "Records", "ThreatRecord", "UnitRecord", "ZoneRecord"]

# slope limits' zone sets and fields kept at once (the classes', the overrides held, a few grown by a margin)
MAX_SLOPE_SETS = 3 + SLOPE_SETS + 4
# heights other than the planner's class's whose threats' fields (each a copy of the packed rows) are kept
MAX_HEIGHTS = 4


@dataclass(slots=True)
class ThreatRecord:
    update: ThreatUpdate
    threat: Threat
    expires_at: float | None
    row: np.ndarray | None = None  # the threat's packed row in the field, once packed (``Records.field``)
    seen: SightKey | None = None  # over terrain, its window's key (``world.terrain.sight_key``)
    blind: bool = False  # over terrain, in force before its window landed (``Records.give_up``)


@dataclass(slots=True)
class ZoneRecord:
    update: ZoneUpdate
    zone: Zone
    expires_at: float | None


class Records:
    """Every unit and threat the world holds, the counts kept as they change, and the field of the threats."""

    def __init__(self, intensity: str = "peak", ground: Ground | None = None) -> None:
        self.book = Units()  # the units' records and their one writer (``units.Units``)
        self.units: dict[str, UnitRecord] = self.book.records
        self.threats: dict[str, ThreatRecord] = {}
        self.zones: dict[str, ZoneRecord] = {}
        self.intensity = intensity
        self._bare: ThreatField | None = None  # the threats' field, built when asked, until they change
        self._field: ThreatField | None = None  # ... and with the zones: until the threats or zones change
        self._zone_set: ZoneSet | None = None  # built when asked, until the zones change
        self.cull: CullIndex | None = None
        self._stats: FieldStats | None = None  # the threats' ``field_stats``: at first use, until they change
        # the terrain's (``world.terrain``): the ground, for a worker rebuilding the field; the windows
        # landed, which the world's rows are masked by; the threats held for theirs, with when to give up
        self.ground, self._barriers = ground, ground_zones(ground)
        self.sight: Looks | None = Looks() if ground is not None else None
        self.held: dict[str, tuple[ThreatRecord, float]] = {}
        # the override slope limits' barrier sets (``world.slopes``): asked off the loop, held, evicted
        self.slopes = Slopes(lambda: (limit_of(r) for r in self.units.values() if r.goal is not None))
        # per slope limit a goal names (``world.mobility``): its zone set and field, while the world's stand
        # and per lead's route key (``team_route``): its zones grown by its followers' corridor
        self._sets: tuple[ZoneSet | None, dict[tuple[int | None, float, tuple[str, ...]], ZoneSet]] = (
            None,
            {},
        )
        self._fields: tuple[ThreatField | None, dict[RouteKey, ThreatField]] = (None, {})
        # per height a unit is seen at, other than the planner's class's (``world.mobility.height_of``): the
        # threats' field with their windows re-heighted (``ThreatField.seen_at``: no sweep) and its cull index
        self._tall: tuple[ThreatField | None, dict[float, tuple[ThreatField, CullIndex | None]]] = (None, {})

    @property
    def field(self) -> ThreatField:
        """The field of the threats in force, in id order, with its cull index and stats, and the zones."""
        if self._field is None:
            if self._bare is None:  # a zone change keeps the threats' field, its cull index and stats
                ordered = [self.threats[k] for k in sorted(self.threats)]
                for t in ordered:  # a threat put packs its row; the others keep theirs
                    if t.row is None:
                        t.row = ThreatField([t.threat], self.intensity, sight=self.sight).packed[0]  # type: ignore[arg-type]
                threats, rows = [t.threat for t in ordered], [t.row for t in ordered]
                self._bare = ThreatField.from_rows(threats, rows, self.intensity)  # type: ignore[arg-type]
                self._bare.sight = self.ground  # a worker rebuilds the field from its threats with it
                self.cull = CullIndex(self._bare.packed) if len(ordered) >= MIN_THREATS else None
                self._stats = None  # a wave changes the threats and starts no mission: ``stats`` when asked
            self._field = self._bare.with_zones(self.zone_set) if self.zones or self._barriers else self._bare
        return self._field

    @property
    def stats(self) -> FieldStats | None:
        """The threats' ``field_stats`` (``resolve``'s figures), computed at first use; ``None`` before ``field``."""
        if self._stats is None and self._bare is not None:
            self._stats = field_stats(self._bare.threats)
        return self._stats

    @property
    def zone_set(self) -> ZoneSet:
        """The zones in force, in id order (``core.zones.ZoneSet``)."""
        if self._zone_set is None:
            self._zone_set = ZoneSet([*self._barriers, *(self.zones[k].zone for k in sorted(self.zones))])
        return self._zone_set

    def zone_set_for(self, slope: int | None, margin_m: float = 0.0, keep: tuple[str, ...] = ()) -> ZoneSet:
        """The zones in force for a unit climbing ``slope`` whole degrees: its barriers, then the keep-out zones
        (``None``, or no terrain: ``zone_set``); with ``margin_m``, each grown by it but those in ``keep``
        (a lead's, for its followers' corridor: ``team_route``)."""
        base = self.zone_set
        if (slope is None or self.ground is None) and margin_m <= 0.0:
            return base
        slope = self._planned(slope)
        of, sets = self._sets
        if of is not base:
            sets = {}
            self._sets = (base, sets)
        key = (slope, margin_m, keep)
        got = sets.get(key)
        if got is None:
            if len(sets) >= MAX_SLOPE_SETS:
                sets.clear()
            if margin_m > 0.0:
                plain = self.zone_set_for(slope)
                grown = self.zone_set_for(slope, margin_m) if keep else team_route.grown_set(plain, margin_m)
                got = grown.plus(z for z in plain if z.id in keep) if keep else grown
            else:
                assert self.ground is not None and slope is not None
                # an override's, built off the loop (an empty set is a set), else a class's: loaded
                held = self.slopes.held.get(slope)
                barriers = held if held is not None else self.ground.barriers(slope)
                got = ZoneSet([*barriers, *(self.zones[k].zone for k in sorted(self.zones))])
            sets[key] = got
        return got

    def field_for(
        self,
        slope: int | None,
        margin_m: float = 0.0,
        keep: tuple[str, ...] = (),
        height_m: float | None = None,
    ) -> ThreatField:
        """``field`` with the zones in force for a unit climbing ``slope`` whole degrees, grown by ``margin_m``
        but ``keep`` (``zone_set_for``), its threats seeing a unit ``height_m`` tall (``None``: the planner's
        class's height, as the windows landed)."""
        base = self.field
        if (slope is None or self.ground is None) and margin_m <= 0.0 and height_m is None:
            return base
        slope = self._planned(slope)
        of, fields = self._fields
        if of is not base:
            fields = {}
            self._fields = (base, fields)
        key = (slope, margin_m, keep, height_m)
        got = fields.get(key)
        if got is None:
            if len(fields) >= MAX_SLOPE_SETS:
                fields.clear()
            zones = self.zone_set_for(slope, margin_m, keep)
            bare = self._seen_at(height_m)[0]
            got = fields[key] = bare.with_zones(zones) if len(zones) else bare
        return got

    def _planned(self, slope: int | None) -> int | None:
        """The limit a unit wanting ``slope`` is planned at now (``world.slopes.Slopes.planned``); the zone
        sets and fields of a limit evicted since are dropped with it."""
        if self.ground is None:
            return slope
        planned = self.slopes.planned(slope)
        if self.slopes.evicted:
            gone = set(self.slopes.evicted)
            self.slopes.evicted.clear()
            sets, fields = self._sets[1], self._fields[1]
            for k in [k for k in sets if k[0] in gone]:
                del sets[k]
            for f in [f for f in fields if f[0] in gone]:
                del fields[f]
        return planned

    def wanting(self, slope: int) -> list[UnitRecord]:
        """The guided units this planner owns whose own limit is ``slope`` (``world.mobility.limit_of``)."""
        return [r for r in self.units.values() if r.owned and r.stepper is not None and limit_of(r) == slope]

    def step_zones(self, route: Callable[[UnitRecord], RouteKey]) -> Callable[[UnitRecord], ZoneSet] | None:
        """Per unit, the zones its step is kept clear of: its own limit's, not a column's margin (``route``
        gives its key); ``None`` when no zone or ground is in force."""
        if self.ground is None and not self.zone_set.zones:
            return None
        return lambda rec: self.field_for(route(rec)[0]).zones

    def cull_for(self, height_m: float | None) -> CullIndex | None:
        """The cull index of the threats in force as they see a unit ``height_m`` tall (``None``: ``cull``):
        the bound on a masked term's gradient is the height's (``core.cull``)."""
        return self.cull_index if height_m is None or self.ground is None else self._seen_at(height_m)[1]

    def _seen_at(self, height_m: float | None) -> tuple[ThreatField, CullIndex | None]:
        """The threats' field seeing a unit ``height_m`` tall, and its cull index: one per height while the
        threats stand, shared by every unit of that height; at most ``MAX_HEIGHTS`` kept."""
        self.field  # noqa: B018 -- builds the threats' field and its cull index
        assert self._bare is not None
        if height_m is None or self.ground is None:
            return self._bare, self.cull
        of, heights = self._tall
        if of is not self._bare:
            heights = {}
            self._tall = (self._bare, heights)
        got = heights.get(height_m)
        if got is None:
            if len(heights) >= MAX_HEIGHTS:
                heights.clear()
            seen = self._bare.seen_at(height_m)
            cull = CullIndex(seen.packed) if self.cull is not None else None
            got = heights[height_m] = (seen, cull)
        return got

    @property
    def cull_index(self) -> CullIndex | None:
        """The cull index of the threats in force (``cull``), the field built first."""
        return self.cull if self.field is not None else None

    def zones_of(self, rec: UnitRecord | None) -> ZoneSet:
        """The zones in force for ``rec``: the barriers of its mobility class, its goal's over its states'
        (``world.mobility``); no record, the planner's class's."""
        return self.zone_set_for(limit_of(rec) if rec is not None else None)

    def field_of(self, rec: UnitRecord) -> ThreatField:
        """The field in force for ``rec``: with the barriers of its mobility class (``world.mobility``)."""
        return self.field_for(limit_of(rec))

    # the world's input handlers name these two here; the writes are the units' owner's
    def drop_mission(self, rec: UnitRecord, why: str) -> None:
        self.book.drop_mission(rec, why)

    def share(self, rec: UnitRecord, mission: Mission) -> None:
        self.book.share(rec, mission)

    def counts(self) -> dict[str, int]:
        """The figures of the status reply these records keep (O(1) but ``units_owned``)."""
        return {
            "units": len(self.units),
            "units_stale": self.book.stale,
            "threats": len(self.threats),
            "zones": len(self.zones),
            "deliberating": self.book.deliberating,
            "units_owned": sum(1 for r in self.units.values() if r.owned),
        }

    # -- threats ----------------------------------------------------------------------
    def put_threat(self, tid: str, record: ThreatRecord) -> ThreatRecord | None:
        """Put a threat; returns the one it replaces, if any."""
        old = self.threats.get(tid)
        self.threats[tid] = record
        self._bare = self._field = None
        return old

    def remove_threat(self, tid: str) -> ThreatRecord | None:
        self._bare = self._field = None
        self.held.pop(tid, None)
        return self.threats.pop(tid, None)

    # -- a threat's sight over terrain (``world.terrain``) ------------------------------
    def hold(self, tid: str, record: ThreatRecord, until: float) -> tuple[bool, SightAsk | None]:
        """Whether ``record`` waits for its window (until ``until`` at most), and the ask for it if not asked yet.

        Not held: no terrain, its window landed already, or the threat in
        force stands on the same key (a put again where it stood).
        """
        if self.sight is None:
            return False, None
        box = reach_box(ThreatField([record.threat], self.intensity).packed[0])  # type: ignore[arg-type]
        record.seen = key = sight_key(record.threat, box)
        now_in = self.threats.get(tid)
        if key in self.sight or (now_in is not None and now_in.seen == key):
            if key not in self.sight and now_in is not None:  # in force blind still: masked when it lands
                record.blind = now_in.blind
            self.held.pop(tid, None)
            return False, None
        before = self.held.get(tid)
        asked = before is not None and before[0].seen == key  # a put again while its window is on its way
        self.held[tid] = (record, before[1] if asked and before is not None else until)
        return True, None if asked else SightAsk(tid, key, record.threat, box)

    def landed(self, tid: str, key: SightKey, window: Window | None) -> tuple[str, ThreatRecord] | None:
        """A window landed: ``("put", record)`` for a threat held for it, ``("seen", record)`` for one in force
        blind, whose row is masked now; ``None``: for a threat since moved or removed (dropped)."""
        if self.sight is None:  # no terrain: nothing was asked
            return None
        held = self.held.get(tid)
        now_in = self.threats.get(tid)
        if held is not None and held[0].seen == key:
            del self.held[tid]
            self.sight.land(key, window, len(self.threats) + 1)
            return "put", held[0]
        if now_in is not None and now_in.seen == key and now_in.blind:
            self.sight.land(key, window, len(self.threats))
            now_in.blind, now_in.row = False, None
            self._bare = self._field = None
            return "seen", now_in
        return None

    def give_up(self, tid: str, now: float) -> ThreatRecord | None:
        """The threat held for its window until ``now``, to take force blind; ``None``: none is due."""
        held = self.held.get(tid)
        if held is None or held[1] > now:
            return None
        del self.held[tid]
        held[0].blind = True
        return held[0]

    def expire(self, tid: str, now: float) -> ThreatRecord | None:
        """Remove a threat whose TTL has run out at ``now`` (one put again since is kept); returns it."""
        t = self.threats.get(tid)
        if t is None or t.expires_at is None or t.expires_at > now:
            return None
        self._bare = self._field = None
        return self.threats.pop(tid)

    # -- zones --------------------------------------------------------------------------
    def _zones_changed(self) -> None:
        self._zone_set = None
        self._field = None

    def put_zone(self, zid: str, record: ZoneRecord) -> ZoneRecord | None:
        """Put a zone; returns the one it replaces, if any."""
        old = self.zones.get(zid)
        self.zones[zid] = record
        self._zones_changed()
        return old

    def remove_zone(self, zid: str) -> ZoneRecord | None:
        gone = self.zones.pop(zid, None)
        if gone is not None:
            self._zones_changed()
        return gone

    def expire_zone(self, zid: str, now: float) -> ZoneRecord | None:
        """Remove a zone whose TTL has run out at ``now`` (one put again since is kept); returns it."""
        z = self.zones.get(zid)
        if z is None or z.expires_at is None or z.expires_at > now:
            return None
        return self.remove_zone(zid)
