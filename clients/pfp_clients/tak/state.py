"""The bridge's state machine: what goes to TAK and to Zenoh for each input, sans-I/O.

Inputs are bytes as they arrived (a CoT event; a Zenoh payload and its key)
and the time; outputs are CoT events to send (already rate-limited per uid),
Zenoh actions (``ZenohPut``/``ZenohDelete``) and the units whose route should
be fetched (a preview query, which the driver makes off this thread's back).
Nothing here opens a socket, reads the clock or logs anything but through the
``log`` callable it is given.

Rules:
- a threat or zone that came from TAK is not sent back to TAK (it is already there);
- a drawn shape (freehand polygon, rectangle, circle) is put as a keep-out
  zone; the planner's own zones are shown as no-go shapes (``cot_out.zone_event``:
  red, remarks ``pfp:keep_out``); a shape deleted in TAK deletes its zone;
  every uid we send starts with ``cot.UID_PREFIX`` and an echo of it is ignored;
- markers are sent again every ``refresh_s`` so TAK clients do not grey them out;
- a unit's route is fetched when it first gets a direction, when its status
  changes, and when the planner replans it, at most once per ``route_min_s``;
  it is sent only when it changed;
- a marker deleted in TAK (``t-x-d-d``, or a version already stale) leaves a
  tombstone until the marker's stale time: a TAK server keeps markers and
  replays them on every connection, ignoring deletes, and a replayed version
  (sent no later than the one deleted) must not come back as a threat.  A
  version sent after the delete is a new marker and lifts the tombstone;
- a link that (re)connects, and a TAK device first heard of (its own position
  report), get the whole picture at once on that link (``Outputs.to_link``):
  threats, units and every unit's route, at most once per ``announce_min_s``.
  A TAK server does not keep routes, so a device that joins late would
  otherwise see none until the next refresh;
- a team member's marker says its team and roles in its remarks (``team_roles``);
- every point carries the origin's altitude as ``hae``, but a route's waypoints with ``ground``
  (``pfp tak --terrain``): the DEM's height there as it is (docs/terrain.md: no geoid applied).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import msgspec
import numpy as np

from pfp_clients.tak import cot, cot_out
from pfp_clients.tak.outputs import Outputs, ZenohDelete, ZenohPut
from pfp_clients.tak.team_roles import TeamRoles, thin
from pfp_clients.tak.tombs import Tombstone, Tombstones
from pfp_service import geo
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from pfp_service.world import translate

__all__ = ["BridgeSettings", "BridgeState", "Tombstone"]


@dataclass(frozen=True, slots=True)
class BridgeSettings:
    """What the bridge is told once, at the edge (``pfp tak`` flags).

    Attributes:
        mission: the Zenoh mission chunk.
        origin: the mission origin the planner's metres are measured from.
        defaults: the shape of a threat made from a hostile marker.
        rate_s: at most one CoT event per uid this often.
        refresh_s: markers are re-sent this often.
        stale_s: how long a marker stays fresh in TAK clients without a refresh.
        route_points: the most waypoints a route is thinned to.
        route_min_s: a unit's route is fetched at most this often.
        announce_min_s: the whole picture goes to one link at most this often.
        device_forget_s: a device silent this long is new again when next heard.
        tombstone_s: how long a tombstone lasts when the deleted marker's stale time is unknown.
        ground: the DEM's height (m, NaN unknown) at arrays of latitudes and longitudes, or None.
    """

    mission: str
    origin: Origin
    defaults: cot.ThreatDefaults = field(default_factory=cot.ThreatDefaults)
    rate_s: float = 1.0
    refresh_s: float = 30.0
    stale_s: float = 90.0
    route_points: int = 50
    route_min_s: float = 2.0
    announce_min_s: float = 1.0
    device_forget_s: float = 60.0
    tombstone_s: float = 86_400.0
    ground: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None


@dataclass(frozen=True, slots=True)
class _Marker:
    """A hostile marker TAK gave us: its uid, and the send and stale times of its latest version."""

    uid: str
    time: float
    stale: float


MAX_DEVICES = 10_000


@dataclass
class _Unit:
    position: tuple[float, float] | None = None
    manned: bool = False
    speed_mps: float = 0.0
    status: str | None = None
    direction: m.Direction | None = None
    route: list[tuple[float, float]] = field(default_factory=list)
    route_remarks: str = ""
    route_hae: list[float] = field(default_factory=list)
    route_asked: float = -1e18
    route_pending: bool = False


class BridgeState:
    """The bridge between a TAK network and the planner's Zenoh keys (see the module docstring)."""

    def __init__(self, settings: BridgeSettings, log: Callable[[str], None] = lambda _m: None) -> None:
        self.s = settings
        self.log = log
        self.limiter = cot_out.RateLimiter(settings.rate_s)
        self.from_tak: dict[str, _Marker] = {}  # threat id -> its marker, for threats TAK gave us
        self.tombs = Tombstones(log)  # marker uid -> what a replay must not revive (tombs.py)
        self.devices: dict[str, float] = {}  # TAK device uid -> when last heard
        self._announce_due: dict[str, float] = {}  # link -> when it gets the whole picture
        self._announced: dict[str, float] = {}  # link -> when it last got it
        self.refused_replays = 0
        self._last_forget = -1e18
        self.threats: dict[str, m.ThreatUpdate] = {}  # threats we show in TAK
        self.zones: dict[str, m.ZoneUpdate] = {}  # the planner's zones we show in TAK (in metres)
        self.zones_from_tak: dict[str, _Marker] = {}  # zone id -> the shape TAK gave us
        self.zones_heard: set[str] = set()  # zone ids put or deleted on Zenoh since the bridge started
        self.units: dict[str, _Unit] = {}
        self.teams = TeamRoles(log)  # a member's marker says its team and roles (on_team)
        self.on_team = self.teams.on_team
        self._last_refresh = -1e18
        self.dropped = 0

    # -- uids ----------------------------------------------------------------
    def _uid(self, what: str, ident: str) -> str:
        return f"{cot.UID_PREFIX}{what}.{self.s.mission}.{ident}"

    def _send(self, uid: str, data: bytes, now: float) -> list[bytes]:
        return self.limiter.offer(uid, data, now)

    @property
    def _hae(self) -> float:
        return float(self.s.origin.alt)

    # -- links and devices -----------------------------------------------------------
    def on_link_up(self, link: str, now: float) -> Outputs:
        """A TAK link (re)connected: it gets the whole picture at the next tick."""
        self._announce_due[link] = now
        return Outputs()

    def _heard_device(self, uid: str, link: str, now: float) -> None:
        last = self.devices.get(uid)
        self.devices[uid] = now
        if last is None or now - last >= self.s.device_forget_s:
            due = max(now, self._announced.get(link, -1e18) + self.s.announce_min_s)
            self._announce_due[link] = min(due, self._announce_due.get(link, due))
        if len(self.devices) > MAX_DEVICES:
            oldest = min(self.devices, key=self.devices.__getitem__)
            del self.devices[oldest]

    def picture(self, now: float) -> list[bytes]:
        """Every marker and route this bridge shows, as of ``now``, past the rate limiter."""
        out = [self._threat_cot(tid, t, now) for tid, t in self.threats.items()]
        out += [self._zone_cot(zid, z, now) for zid, z in self.zones.items()]
        for unit, u in self.units.items():
            data = None if u.direction is None else self._unit_cot(unit, u, u.direction, now)
            if data is not None:
                out.append(data)
            if len(u.route) >= 2:
                out.append(self._route_cot(unit, u, now))
        return out

    # -- tombstones ----------------------------------------------------------------
    @property
    def tombstones(self) -> dict[str, Tombstone]:
        return self.tombs.by_uid

    @property
    def tombstones_version(self) -> int:
        return self.tombs.version

    def _forget(self, now: float) -> None:
        if now - self._last_forget < 1.0:
            return  # a scan a second is plenty for what lives minutes
        self._last_forget = now
        self.tombs.expire(now)
        for uid in [u for u, t in self.devices.items() if now - t >= self.s.device_forget_s]:
            del self.devices[uid]
        for tid in [i for i, mk in self.from_tak.items() if mk.stale <= now]:
            del self.from_tak[tid]  # the planner lets it go by its TTL
        for zid in [i for i, mk in self.zones_from_tak.items() if mk.stale <= now]:
            del self.zones_from_tak[zid]

    def restore_tombstones(self, saved: dict[str, Tombstone], now: float) -> None:
        """Tombstones kept from an earlier run (the driver loads them); expired ones are dropped."""
        for uid, t in saved.items():
            self.tombs.bury(uid, t.after, t.until, now, t.source)

    # -- TAK -> planner --------------------------------------------------------
    def on_cot(self, data: bytes, now: float, source: str = "TAK") -> Outputs:
        """A CoT event from TAK: a hostile marker puts a threat, a delete removes it."""
        out = Outputs()
        try:
            ev = cot.read_event(data)
            shape = ev.type in cot.SHAPE_TYPES
            change = cot.to_zone_change(ev, now) if shape else cot.to_threat_change(ev, self.s.defaults, now)
        except cot.CotError as exc:
            self.dropped += 1
            self.log(f"dropped a CoT event from {source}: {exc}")
            return out
        if not ev.uid.startswith(cot.UID_PREFIX) and (ev.device or ev.type.startswith("a-f-")):
            self._heard_device(ev.uid, source, now)
        if isinstance(change, cot.ThreatRemoved):
            seen = self.from_tak.pop(change.id, None)
            drawn = self.zones_from_tak.pop(change.id, None)
            if drawn is not None:  # a shape deleted (or gone stale): its zone goes
                out.zenoh.append(ZenohDelete(keys.zone(self.s.mission, change.id)))
                self.tombs.bury(change.uid, max(ev.time, drawn.time), max(ev.stale, drawn.stale), now, source)
            elif seen is not None:
                out.zenoh.append(ZenohDelete(keys.threat(self.s.mission, change.id)))
                self.tombs.bury(change.uid, max(ev.time, seen.time), max(ev.stale, seen.stale), now, source)
            else:
                self.tombs.bury(change.uid, ev.time, max(ev.stale, now + self.s.tombstone_s), now, source)
            return out
        if change is None:
            return out
        tomb = self.tombs.get(change.uid)
        if tomb is not None:
            if ev.time <= tomb.after:
                self.refused_replays += 1  # the server's copy of a deleted marker
                if ev.stale > tomb.until:
                    self.tombs.extend(change.uid, ev.stale)
                return out
            self.tombs.lift(change.uid)  # sent after the delete: a new marker
        if isinstance(change, cot.ZonePut):
            return self._zone_from_tak(change, ev, now, source)
        body = dict(change.body)
        try:
            body["position"] = list(self.s.origin.localise_point(m.LatLon(**body["position"])))  # type: ignore[arg-type]
            update = msgspec.convert(body, m.ThreatUpdate)
        except (InputError, msgspec.ValidationError, ValueError) as exc:
            self.dropped += 1
            self.log(f"dropped hostile marker {change.uid!r} from {source}: {exc}")
            return out
        self.from_tak[change.id] = _Marker(change.uid, ev.time, ev.stale)
        out.zenoh.append(ZenohPut(keys.threat(self.s.mission, change.id), m.encode(update)))
        return out

    def _zone_from_tak(self, change: cot.ZonePut, ev: cot.CotEvent, now: float, source: str) -> Outputs:
        """A drawn shape as a zone put; one the planner's rules refuse is dropped here, with its reason."""
        out = Outputs()
        try:
            update = m.decode_zone(msgspec.json.encode(change.body), origin=self.s.origin)
        except InputError as exc:
            self.dropped += 1
            self.log(f"dropped shape {change.uid!r} from {source}: not a keep-out zone: {exc}")
            return out
        self.zones_from_tak[change.id] = _Marker(change.uid, ev.time, ev.stale)
        out.zenoh.append(ZenohPut(keys.zone(self.s.mission, change.id), m.encode(update)))
        return out

    # -- planner -> TAK --------------------------------------------------------
    def _zone_cot(self, zid: str, z: m.ZoneUpdate, now: float) -> bytes:
        stale = min(z.ttl_s, self.s.stale_s) if z.ttl_s is not None else self.s.stale_s
        remarks = f"{cot.NO_GO_REMARK} zone {zid}: no unit's path enters it"
        uid = self._uid("zone", zid)
        if z.circle is not None:
            centre = self.s.origin.to_geodetic(*z.circle.centre)
            return cot_out.zone_event(
                uid, None, centre, z.circle.radius_m, now, stale, f"no-go {zid}", remarks, self._hae
            )
        rings = z.polygon or [[(0.0, 0.0)]]
        shell = np.asarray(rings[0][:-1], dtype=float)
        ll = [(float(a), float(b)) for a, b in self.s.origin.to_geodetic_many(shell)]
        if len(rings) > 1:  # TAK's shapes have no holes: the outline alone, and say so
            remarks += f" (its {len(rings) - 1} hole(s) are not drawn: they are open ground)"
        centre = (sum(p[0] for p in ll) / len(ll), sum(p[1] for p in ll) / len(ll))
        return cot_out.zone_event(uid, ll, centre, None, now, stale, f"no-go {zid}", remarks, self._hae)

    def on_zone(self, key: str, payload: bytes | None, now: float) -> Outputs:
        """A zone put (``payload``) or deleted (``None``) on Zenoh: shown in TAK as a no-go shape."""
        out = Outputs()
        zid = keys.parse(key).id
        self.zones_heard.add(zid)
        if zid in self.zones_from_tak:
            return out  # TAK's own shape: it is on the maps already
        if payload is None:
            z = self.zones.pop(zid, None)
            if z is not None:
                uid = self._uid("zone", zid)
                typ = "u-d-c-c" if z.circle is not None else "u-d-f"
                lat, lon = self.s.origin.to_geodetic(
                    *(z.circle.centre if z.circle else (z.polygon or [[(0, 0)]])[0][0])
                )
                out.cot += self._send(
                    uid, cot_out.delete_event(f"{uid}.delete", uid, typ, lat, lon, now, self._hae), now
                )
            return out
        try:
            z = m.decode_zone(payload, origin=self.s.origin)
        except InputError as exc:
            self.log(f"ignored zone {zid}: {exc}")
            return out
        self.zones[zid] = z
        out.cot += self._send(self._uid("zone", zid), self._zone_cot(zid, z, now), now)
        return out

    def _threat_cot(self, tid: str, t: m.ThreatUpdate, now: float) -> bytes:
        lat, lon = self.s.origin.to_geodetic(*t.position)
        stale = min(t.ttl_s, self.s.stale_s) if t.ttl_s is not None else self.s.stale_s
        rows = [*translate.describe(t), ("weight", f"{t.weight:g}")]
        remarks = f"pfp threat {tid}: " + ", ".join(f"{label} {value}" for label, value in rows)
        return cot_out.threat_event(
            self._uid("threat", tid), lat, lon, now, stale, t.facing_deg, remarks, f"threat {tid}", self._hae
        )

    def on_threat(self, key: str, payload: bytes | None, now: float) -> Outputs:
        """A threat put (``payload``) or deleted (``None``) on Zenoh."""
        out = Outputs()
        tid = keys.parse(key).id
        if tid in self.from_tak:
            return out  # TAK's own marker: it is on the maps already
        if payload is None:
            t = self.threats.pop(tid, None)
            if t is not None:
                lat, lon = self.s.origin.to_geodetic(*t.position)
                uid = self._uid("threat", tid)
                out.cot += self._send(
                    uid, cot_out.delete_event(f"{uid}.delete", uid, "a-h-G", lat, lon, now, self._hae), now
                )
            return out
        try:
            t = m.decode_threat(payload, origin=self.s.origin)
            cot_bytes = self._threat_cot(tid, t, now)
        except (InputError, ValueError) as exc:  # ValueError: a shape the planner refuses too
            self.log(f"ignored threat {tid}: {exc}")
            return out
        self.threats[tid] = t
        out.cot += self._send(self._uid("threat", tid), cot_bytes, now)
        return out

    def on_zones_in_force(self, zones: list[m.ZoneSummary], now: float) -> Outputs:
        """The zones a planner held when the bridge started (its world reply): shown as if put now.

        A zone put or deleted on Zenoh since is newer, and is left as heard.
        """
        out = Outputs()
        for z in zones:
            if z.id not in self.zones_heard:
                update = msgspec.structs.replace(z.zone, ttl_s=z.ttl_s)  # the time left
                out.extend(self.on_zone(keys.zone(self.s.mission, z.id), m.encode(update), now))
        return out

    def on_state(self, key: str, payload: bytes) -> None:
        """A unit's reported state: where its marker goes."""
        unit = keys.parse(key).id
        try:
            st = m.decode_unit_state(payload, origin=self.s.origin)
        except InputError:
            return  # the planner rejects it with a reason; the bridge just has no position
        u = self.units.setdefault(unit, _Unit())
        u.position = st.position
        if st.kind is not None:
            u.manned = st.kind is m.UnitKind.MANNED
        if st.speed_mps is not None:
            u.speed_mps = st.speed_mps

    def _unit_cot(self, unit: str, u: _Unit, d: m.Direction, now: float) -> bytes | None:
        if u.position is None:
            return None
        lat, lon = self.s.origin.to_geodetic(*u.position)
        course = d.true_bearing_deg
        if course is None and d.vector != (0.0, 0.0):
            course = geo.true_bearing_deg(self.s.origin, u.position, d.vector)
        parts = [f"pfp {d.status.value}"]
        if d.distance_to_goal is not None:
            parts.append(f"{d.distance_to_goal:.0f} m to goal")
        parts.append(f"threat level {d.threat_level:.3g}")
        if team := self.teams.remark(unit):
            parts.append(team)
        if d.reason:
            parts.append(d.reason)
        return cot_out.unit_event(
            self._uid("unit", unit),
            u.manned,
            lat,
            lon,
            now,
            self.s.stale_s,
            course,
            u.speed_mps,
            "; ".join(parts),
            unit,
            self._hae,
        )

    def on_direction(self, key: str, payload: bytes, now: float) -> Outputs:
        """A direction for a unit: its marker's course and remarks; a new status asks for the route."""
        out = Outputs()
        unit = keys.parse(key).id
        try:
            d = m.decode_direction(payload)
        except InputError:
            return out
        u = self.units.setdefault(unit, _Unit())
        first = u.direction is None
        u.direction = d
        data = self._unit_cot(unit, u, d, now)
        if data is not None:
            out.cot += self._send(self._uid("unit", unit), data, now)
        if first or d.status.value != u.status:
            out.routes += self._ask_route(unit, now)
        u.status = d.status.value
        return out

    def on_event(self, payload: bytes, now: float) -> Outputs:
        """A planner event: a replan asks for the routes of the units it names."""
        out = Outputs()
        try:
            ev = m.decode_event(payload)
        except InputError:
            return out
        if isinstance(ev, m.ReplanEvent):
            for unit in ev.units:
                out.routes += self._ask_route(unit, now)
        return out

    def _ask_route(self, unit: str, now: float) -> list[str]:
        u = self.units.setdefault(unit, _Unit())
        if now - u.route_asked >= self.s.route_min_s:
            u.route_asked = now
            u.route_pending = False
            return [unit]
        u.route_pending = True  # asked again too soon: tick() asks once the interval is over
        return []

    def on_route(
        self, unit: str, path: list[tuple[float, float]], status: str, length_m: float, now: float
    ) -> Outputs:
        """The unit's planned path (a live preview), sent as a route when it changed."""
        out = Outputs()
        if len(path) < 2:
            return out
        pts = thin(np.asarray(path, dtype=float), self.s.route_points)
        ll = [(float(a), float(b)) for a, b in self.s.origin.to_geodetic_many(pts)]
        u = self.units.setdefault(unit, _Unit())
        if len(ll) == len(u.route) and np.allclose(ll, u.route, atol=1e-7, rtol=0.0):
            return out
        u.route = ll
        hae = np.full(len(ll), self._hae)
        if self.s.ground is not None:  # off the DEM, or on no-data: the origin's altitude, as without one
            z = self.s.ground(np.array([p[0] for p in ll]), np.array([p[1] for p in ll]))
            hae = np.where(np.isfinite(z), z, hae)
        u.route_hae = [float(h) for h in hae]
        u.route_remarks = f"pfp route for {unit}: {status}, {length_m:.0f} m, {len(ll)} waypoints"
        out.cot += self._send(self._uid("route", unit), self._route_cot(unit, u, now), now)
        return out

    def _route_cot(self, unit: str, u: _Unit, now: float) -> bytes:
        uid = self._uid("route", unit)
        return cot_out.route_event(
            uid, u.route, now, self.s.stale_s, f"route {unit}", u.route_remarks, u.route_hae or self._hae
        )

    def tick(self, now: float) -> Outputs:
        """Held-back events whose turn came, pictures due, the periodic refresh, routes asked for too soon."""
        out = Outputs(cot=self.limiter.due(now))
        for unit, u in self.units.items():
            if u.route_pending and now - u.route_asked >= self.s.route_min_s:
                out.routes += self._ask_route(unit, now)
        due = [link for link, t in self._announce_due.items() if t <= now]
        if due:
            picture = self.picture(now)
            for link in due:
                del self._announce_due[link]
                self._announced[link] = now
                out.to_link += [(link, data) for data in picture]
        self._forget(now)
        if now - self._last_refresh < self.s.refresh_s:
            return out
        self._last_refresh = now
        for tid, t in self.threats.items():
            out.cot += self._send(self._uid("threat", tid), self._threat_cot(tid, t, now), now)
        for zid, z in self.zones.items():
            out.cot += self._send(self._uid("zone", zid), self._zone_cot(zid, z, now), now)
        for unit, u in self.units.items():
            data = None if u.direction is None else self._unit_cot(unit, u, u.direction, now)
            if data is not None:
                out.cot += self._send(self._uid("unit", unit), data, now)
            if len(u.route) >= 2:
                out.cot += self._send(self._uid("route", unit), self._route_cot(unit, u, now), now)
        return out
