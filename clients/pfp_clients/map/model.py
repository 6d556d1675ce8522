"""What the operator's map knows about a mission, and what changed since the browser last heard.

Sans-I/O, as the planner's world is: the Zenoh callbacks decode each sample
into one of the ``Seen`` inputs (``samples``), the server applies them in batches with
``MapModel.apply(inputs, now)``, and ``take_delta(now)`` returns the JSON-ready
changes since the previous call (or ``None``).  ``snapshot(now)`` is the whole
picture for a browser that has just connected.  ``now`` is wall-clock Unix
seconds, passed in; nothing here reads a clock.

Staleness follows the planner's rule from the outside: a unit is stale when it
has not reported for ``stale_s``, or when its liveliness token has stayed gone
for ``debounce_s`` (a router restart withdraws every token for a few seconds).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import msgspec

from pfp_clients.map.deltas import merge_deltas
from pfp_clients.map.geometry import ThreatView, threat_view
from pfp_clients.map.samples import (
    AliveSeen,
    DirectionSeen,
    EventSeen,
    GoalSeen,
    Input,
    StateSeen,
    StatusSeen,
    TeamSeen,
    ThreatSeen,
    WorldSeen,
    ZoneSeen,
)
from pfp_clients.map.team_layer import TeamLayer
from pfp_service.errors import InputError
from pfp_service.wire import (
    Event,
    ForgottenEvent,
    RejectedEvent,
    StaleEvent,
    ThreatUpdate,
    WorldSnapshot,
    keys,
)
from pfp_service.wire.messages import ZoneUpdate

__all__ = [
    "MAX_REJECTED_GROUPS",
    "MapModel",
    "eta_s",
    "merge_deltas",
]


# -- what is kept -----------------------------------------------------------------
def _cm(p: tuple[float, float]) -> tuple[float, float]:
    """A position rounded to the centimetre: what the page can show, in a third of the JSON."""
    return (round(p[0], 2), round(p[1], 2))


@dataclass(slots=True)
class _Unit:
    id: str
    kind: str | None = None
    position: tuple[float, float] | None = None
    heading_deg: float | None = None
    speed_mps: float | None = None
    last_seen: float | None = None
    status: str | None = None
    reason: str = ""
    route: str = ""  # what the route behind its direction is (docs/wire.md's statuses)
    progress: str = ""  # what its reports show: moving, holding, stalled
    distance_to_goal: float | None = None
    threat_level: float = 0.0
    lookahead: list[tuple[float, float]] = field(default_factory=list)
    goal: tuple[float, float] | None = None
    alive: bool | None = None
    gone_since: float | None = None
    said_stale: bool = False  # the planner's stale event, until the unit reports again
    stale: bool = False
    track: deque[tuple[float, float]] = field(default_factory=deque)
    track_new: list[tuple[float, float]] = field(default_factory=list)
    track_t: float = -math.inf

    def view(self, track: list[tuple[float, float]] | None) -> dict[str, Any]:
        out: dict[str, Any] = {
            "id": self.id,
            "kind": self.kind,
            "position": _cm(self.position) if self.position is not None else None,
            "heading_deg": self.heading_deg,
            "speed_mps": self.speed_mps,
            "last_seen": self.last_seen,
            "status": self.status,
            "reason": self.reason,
            "route": self.route,
            "progress": self.progress,
            "distance_to_goal": self.distance_to_goal,
            "threat_level": self.threat_level,
            "lookahead": [_cm(p) for p in self.lookahead],
            "goal": self.goal,
            "alive": self.alive,
            "stale": self.stale,
        }
        if track is not None:
            out["track"] = track
        else:
            out["track_add"] = self.track_new
        return out


def _zone_view(zone_id: str, z: ZoneUpdate, now: float, ttl_left_s: float | None) -> dict[str, Any]:
    """A zone as the page draws it: its rings (metres; a polygon's outer ring first) or its circle."""
    return {
        "id": zone_id,
        "kind": z.kind,
        "polygon": None if z.polygon is None else [[_cm(p) for p in ring] for ring in z.polygon],
        "circle": None
        if z.circle is None
        else {"centre": _cm(z.circle.centre), "radius_m": z.circle.radius_m},
        "ttl_s": z.ttl_s,
        "put_at": now,
        "expires_at": None if ttl_left_s is None else now + ttl_left_s,
    }


MAX_REJECTED_GROUPS = 100


def _rejected_group(ev: RejectedEvent) -> tuple[str, str]:
    """Rejections are counted per (kind of key, field, reason): a flood of one mistake is one line."""
    try:
        what = keys.parse(ev.key).kind.value
    except InputError:
        what = "other"
    return f"{what}|{ev.field}|{ev.reason}", what


class MapModel:
    """Units, threats, events and planner status as the map shows them.

    Args:
        stale_s: a unit silent this long is stale (the planner's ``unit_stale_s``).
        debounce_s: a unit whose liveliness token stays gone this long is stale.
        track_max: positions kept per unit for its track.
        track_interval_s: at most one track position per this long (10 Hz reports would
            otherwise make the track a fresh array per unit per frame).
        events_max: events kept for the feed (rejections are aggregated, not counted here).
    """

    def __init__(
        self,
        stale_s: float = 10.0,
        debounce_s: float = 2.0,
        track_max: int = 200,
        events_max: int = 100,
        track_interval_s: float = 0.5,
    ) -> None:
        self.track_interval_s = track_interval_s
        self.stale_s = stale_s
        self.debounce_s = debounce_s
        self.track_max = track_max
        self.units: dict[str, _Unit] = {}
        self.threats: dict[str, ThreatView] = {}
        self.zones: dict[str, dict[str, Any]] = {}  # zone id -> its view
        self.teams = TeamLayer()  # teams, and their leads' tracks (the cleared corridors)
        self.zone_updates: dict[str, ZoneUpdate] = {}  # zone id -> as put (metres), for the GeoJSON export
        self._dirty_zones: set[str] = set()
        self._removed_zones: set[str] = set()
        self.events: deque[dict[str, Any]] = deque(maxlen=events_max)
        self.rejected: dict[str, dict[str, Any]] = {}
        self.status: dict[str, dict[str, Any]] = {}
        self._dirty_units: set[str] = set()
        self._removed_units: set[str] = set()
        self._dirty_threats: set[str] = set()
        self._removed_threats: set[str] = set()
        self._new_events: list[dict[str, Any]] = []
        self._dirty_rejected: set[str] = set()
        self._dirty_status: set[str] = set()

    # -- inputs -------------------------------------------------------------------
    def _unit(self, unit_id: str) -> _Unit:
        u = self.units.get(unit_id)
        if u is None:
            u = self.units[unit_id] = _Unit(unit_id)
            self._removed_units.discard(unit_id)
        self._dirty_units.add(unit_id)
        return u

    def apply(self, inputs: Iterable[Input], now: float) -> None:
        """Fold decoded samples into the picture, in arrival order."""
        for msg in inputs:
            match msg:
                case StateSeen(unit_id, st):
                    u = self._unit(unit_id)
                    pos = (float(st.position[0]), float(st.position[1]))
                    u.position = pos
                    u.last_seen = now
                    u.said_stale = False
                    if st.kind is not None:
                        u.kind = str(st.kind)
                    if st.speed_mps is not None:
                        u.speed_mps = st.speed_mps
                    if st.heading_deg is not None:
                        u.heading_deg = st.heading_deg
                    self.teams.moved(unit_id, pos)
                    if now - u.track_t >= self.track_interval_s and (not u.track or u.track[-1] != _cm(pos)):
                        u.track_t = now
                        u.track.append(_cm(pos))
                        u.track_new.append(_cm(pos))
                        if len(u.track) > self.track_max:
                            u.track.popleft()
                case DirectionSeen(unit_id, d):
                    u = self._unit(unit_id)
                    u.status = str(d.status)
                    u.reason = d.reason
                    u.route = d.route.value
                    u.progress = d.progress.value
                    u.distance_to_goal = d.distance_to_goal
                    u.threat_level = d.threat_level
                    u.lookahead = [(float(x), float(y)) for x, y in d.lookahead]
                    if d.heading_deg is not None:
                        u.heading_deg = d.heading_deg
                case GoalSeen(unit_id, goal):
                    self._unit(unit_id).goal = None if goal is None else goal.position
                case ThreatSeen(threat_id, update):
                    if update is None:
                        if self.threats.pop(threat_id, None) is not None:
                            self._removed_threats.add(threat_id)
                            self._dirty_threats.discard(threat_id)
                    else:
                        self._put_threat(threat_id, update, now, update.ttl_s)
                case ZoneSeen(zone_id, zupdate):
                    if zupdate is None:
                        self._drop_zone(zone_id)
                    else:
                        self._put_zone(zone_id, zupdate, now, zupdate.ttl_s)
                case AliveSeen(unit_id, alive):
                    u = self._unit(unit_id)
                    u.alive = alive
                    u.gone_since = None if alive else now
                case EventSeen(ev):
                    self._on_event(ev, now)
                case StatusSeen(st):
                    self.status[st.planner] = {**msgspec.to_builtins(st), "received_at": now}
                    self._dirty_status.add(st.planner)
                case WorldSeen(world):
                    self._on_world(world, now)
                case TeamSeen(team_id, team):
                    self.teams.put(team_id, team)

    def _put_threat(self, threat_id: str, update: ThreatUpdate, now: float, ttl_left_s: float | None) -> None:
        try:
            self.threats[threat_id] = threat_view(threat_id, update, now, ttl_left_s)
        except ValueError:  # a shape or parameters the planner refuses too: it keeps what it had, so the map
            return
        self._dirty_threats.add(threat_id)
        self._removed_threats.discard(threat_id)

    def _put_zone(self, zone_id: str, z: ZoneUpdate, now: float, ttl_left_s: float | None) -> None:
        self.zones[zone_id] = _zone_view(zone_id, z, now, ttl_left_s)
        self.zone_updates[zone_id] = z
        self._dirty_zones.add(zone_id)
        self._removed_zones.discard(zone_id)

    def _drop_zone(self, zone_id: str) -> None:
        if self.zones.pop(zone_id, None) is not None:
            self.zone_updates.pop(zone_id, None)
            self._removed_zones.add(zone_id)
            self._dirty_zones.discard(zone_id)

    def _on_world(self, world: WorldSnapshot, now: float) -> None:
        """Fill in what the samples have not told yet; a sample seen since is newer, so it wins."""
        for s in world.units:
            u = self._unit(s.id)
            if u.position is None and s.position is not None:
                u.position = (float(s.position[0]), float(s.position[1]))
                u.track.append(_cm(u.position))
                u.track_new.append(_cm(u.position))
                u.last_seen = None if s.last_seen_s is None else now - s.last_seen_s
            if u.kind is None and s.kind is not None:
                u.kind = str(s.kind)
            if u.status is None and s.status is not None:
                u.status = str(s.status)
                u.reason = s.reason
                u.distance_to_goal = s.distance_to_goal
            if u.goal is None and s.goal is not None:
                u.goal = s.goal
        for t in world.threats:
            if t.id not in self.threats:
                self._put_threat(t.id, t.threat, now, t.ttl_s)
        for z in world.zones:
            if z.id not in self.zones:
                self._put_zone(z.id, z.zone, now, z.ttl_s)
        for tm in world.teams:
            if tm.id not in self.teams.teams:
                self.teams.put(tm.id, tm.team)

    def _on_event(self, ev: Event, now: float) -> None:
        t = ev.t if ev.t is not None else now
        if isinstance(ev, RejectedEvent):
            group, what = _rejected_group(ev)
            field_path, reason = ev.field, ev.reason
            if group not in self.rejected and len(self.rejected) >= MAX_REJECTED_GROUPS:
                # reasons that quote the value (a position outside the bounds) make new groups
                # without end: past the cap, count them per kind of key
                group, field_path, reason = f"{what}|*|other reasons", "*", "other reasons"
            agg = self.rejected.get(group)
            if agg is None:
                agg = self.rejected[group] = {
                    "id": group,
                    "key_kind": what,
                    "field": field_path,
                    "reason": reason,
                    "count": 0,
                    "first_t": t,
                }
            agg["count"] += 1
            agg["last_t"] = t
            agg["last_key"] = ev.key
            self._dirty_rejected.add(group)
            return
        if isinstance(ev, StaleEvent) and ev.unit in self.units:
            self._unit(ev.unit).said_stale = True
        if isinstance(ev, ForgottenEvent) and self.units.pop(ev.unit, None) is not None:
            self._dirty_units.discard(ev.unit)
            self._removed_units.add(ev.unit)
        view = {**msgspec.to_builtins(ev), "t": t}
        self.events.append(view)
        self._new_events.append(view)

    # -- time ---------------------------------------------------------------------
    def _age_out(self, now: float) -> None:
        for u in self.units.values():
            silent = u.last_seen is not None and now - u.last_seen > self.stale_s
            gone = u.gone_since is not None and now - u.gone_since >= self.debounce_s
            stale = silent or gone or u.said_stale
            if stale != u.stale:
                u.stale = stale
                self._dirty_units.add(u.id)
        for tid in [t.id for t in self.threats.values() if t.expires_at is not None and t.expires_at <= now]:
            del self.threats[tid]
            self._removed_threats.add(tid)
            self._dirty_threats.discard(tid)
        for zid in [
            i for i, z in self.zones.items() if z["expires_at"] is not None and z["expires_at"] <= now
        ]:
            self._drop_zone(zid)

    # -- outputs ------------------------------------------------------------------
    def take_delta(self, now: float) -> dict[str, Any] | None:
        """What changed since the last call (JSON-ready), or ``None`` when nothing did."""
        self._age_out(now)
        out: dict[str, Any] = {}
        if self._dirty_units:
            out["units"] = {uid: self.units[uid].view(None) for uid in self._dirty_units}
            for uid in self._dirty_units:
                self.units[uid].track_new = []
        if self._removed_units:
            out["units_removed"] = sorted(self._removed_units)
        if self._dirty_threats:
            out["threats"] = {tid: self.threats[tid].view() for tid in self._dirty_threats}
        if self._removed_threats:
            out["threats_removed"] = sorted(self._removed_threats)
        if self._dirty_zones:
            out["zones"] = {zid: self.zones[zid] for zid in self._dirty_zones}
        if self._removed_zones:
            out["zones_removed"] = sorted(self._removed_zones)
        self._dirty_zones, self._removed_zones = set(), set()
        out.update(self.teams.take())
        if self._new_events:
            out["events"] = self._new_events[-(self.events.maxlen or 100) :]
        if self._dirty_rejected:
            out["rejected"] = {g: dict(self.rejected[g]) for g in self._dirty_rejected}
        if self._dirty_status:
            out["status"] = {p: self.status[p] for p in self._dirty_status}
        self._dirty_units, self._dirty_threats, self._removed_threats = set(), set(), set()
        self._removed_units = set()
        self._new_events, self._dirty_rejected, self._dirty_status = [], set(), set()
        if not out:
            return None
        return {"type": "delta", "now": now, **out}

    def snapshot(self, now: float) -> dict[str, Any]:
        """Everything, for a browser that has just connected (call right after ``take_delta``)."""
        return {
            "type": "snapshot",
            "now": now,
            "units": {uid: u.view(list(u.track)) for uid, u in self.units.items()},
            "threats": {tid: t.view() for tid, t in self.threats.items()},
            "zones": dict(self.zones),
            "teams": self.teams.all(),
            "events": list(self.events),
            "rejected": {g: dict(a) for g, a in self.rejected.items()},
            "status": dict(self.status),
        }

    def speed_of(self, unit_id: str) -> float | None:
        """The unit's last reported speed in m/s (for a preview's ETA), if it reported one."""
        u = self.units.get(unit_id)
        return None if u is None else u.speed_mps


def eta_s(length_m: float, speed_mps: float | None) -> float | None:
    """Seconds to walk ``length_m`` at ``speed_mps``; None without a positive speed."""
    if speed_mps is None or not speed_mps > 0 or not math.isfinite(length_m):
        return None
    return length_m / speed_mps
