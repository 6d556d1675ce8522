"""The bridge's state machine: what goes to TAK and to Zenoh for each input, sans-I/O.

Inputs are bytes as they arrived (a CoT event; a Zenoh payload and its key)
and the time; outputs are CoT events to send (already rate-limited per uid),
Zenoh actions (``ZenohPut``/``ZenohDelete``) and the units whose route should
be fetched (a preview query, which the driver makes off this thread's back).
Nothing here opens a socket, reads the clock or logs anything but through the
``log`` callable it is given.

Rules:
- a threat that came from TAK is not sent back to TAK (it is already there);
  every uid we send starts with ``cot.UID_PREFIX`` and an echo of it is ignored;
- markers are sent again every ``refresh_s`` so TAK clients do not grey them out;
- a unit's route is fetched when it first gets a direction, when its status
  changes, and when the planner replans it, at most once per ``route_min_s``;
  it is sent only when it changed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import msgspec
import numpy as np

from pfp_service import geo
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.tak import cot
from pfp_service.wire import keys
from pfp_service.wire import messages as m

__all__ = ["BridgeSettings", "BridgeState", "Outputs", "ZenohDelete", "ZenohPut"]


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
    """

    mission: str
    origin: Origin
    defaults: cot.ThreatDefaults = field(default_factory=cot.ThreatDefaults)
    rate_s: float = 1.0
    refresh_s: float = 30.0
    stale_s: float = 90.0
    route_points: int = 50
    route_min_s: float = 2.0


@dataclass(frozen=True, slots=True)
class ZenohPut:
    key: str
    payload: bytes


@dataclass(frozen=True, slots=True)
class ZenohDelete:
    key: str


@dataclass
class Outputs:
    """What one input produced."""

    cot: list[bytes] = field(default_factory=list)
    zenoh: list[ZenohPut | ZenohDelete] = field(default_factory=list)
    routes: list[str] = field(default_factory=list)

    def extend(self, other: Outputs) -> None:
        self.cot += other.cot
        self.zenoh += other.zenoh
        self.routes += other.routes


@dataclass
class _Unit:
    position: tuple[float, float] | None = None
    manned: bool = False
    speed_mps: float = 0.0
    status: str | None = None
    direction: m.Direction | None = None
    route: list[tuple[float, float]] = field(default_factory=list)
    route_remarks: str = ""
    route_asked: float = -1e18
    route_pending: bool = False


def _thin(path: np.ndarray, n: int) -> np.ndarray:
    if len(path) <= n:
        return path
    idx = np.unique(np.round(np.linspace(0, len(path) - 1, n)).astype(int))
    return path[idx]


class BridgeState:
    """The bridge between a TAK network and the planner's Zenoh keys (see the module docstring)."""

    def __init__(self, settings: BridgeSettings, log: Callable[[str], None] = lambda _m: None) -> None:
        self.s = settings
        self.log = log
        self.limiter = cot.RateLimiter(settings.rate_s)
        self.from_tak: dict[str, str] = {}  # threat id -> marker uid, for threats TAK gave us
        self.threats: dict[str, m.ThreatUpdate] = {}  # threats we show in TAK
        self.units: dict[str, _Unit] = {}
        self._last_refresh = -1e18
        self.dropped = 0

    # -- uids ----------------------------------------------------------------
    def _uid(self, what: str, ident: str) -> str:
        return f"{cot.UID_PREFIX}{what}.{self.s.mission}.{ident}"

    def _send(self, uid: str, data: bytes, now: float) -> list[bytes]:
        return self.limiter.offer(uid, data, now)

    # -- TAK -> planner --------------------------------------------------------
    def on_cot(self, data: bytes, now: float, source: str = "TAK") -> Outputs:
        """A CoT event from TAK: a hostile marker puts a threat, a delete removes it."""
        out = Outputs()
        try:
            change = cot.to_threat_change(cot.read_event(data), self.s.defaults)
        except cot.CotError as exc:
            self.dropped += 1
            self.log(f"dropped a CoT event from {source}: {exc}")
            return out
        if isinstance(change, cot.ThreatRemoved):
            if self.from_tak.pop(change.id, None) is not None:
                out.zenoh.append(ZenohDelete(keys.threat(self.s.mission, change.id)))
            return out
        if change is None:
            return out
        body = dict(change.body)
        try:
            body["position"] = list(self.s.origin.localise_point(m.LatLon(**body["position"])))  # type: ignore[arg-type]
            update = msgspec.convert(body, m.ThreatUpdate)
        except (InputError, msgspec.ValidationError, ValueError) as exc:
            self.dropped += 1
            self.log(f"dropped hostile marker {change.uid!r} from {source}: {exc}")
            return out
        self.from_tak[change.id] = change.uid
        out.zenoh.append(ZenohPut(keys.threat(self.s.mission, change.id), m.encode(update)))
        return out

    # -- planner -> TAK --------------------------------------------------------
    def _threat_cot(self, tid: str, t: m.ThreatUpdate, now: float) -> bytes:
        lat, lon = self.s.origin.to_geodetic(*t.position)
        stale = min(t.ttl_s, self.s.stale_s) if t.ttl_s is not None else self.s.stale_s
        remarks = (
            f"pfp threat {tid}: sigma_range {t.sigma_range:g} m, sigma_lateral {t.sigma_lateral:g} m, "
            f"skew {t.skew:g}, weight {t.weight:g}"
        )
        return cot.threat_event(
            self._uid("threat", tid), lat, lon, now, stale, t.facing_deg, remarks, f"threat {tid}"
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
                    uid, cot.delete_event(f"{uid}.delete", uid, "a-h-G", lat, lon, now), now
                )
            return out
        try:
            t = m.decode_threat(payload, origin=self.s.origin)
        except InputError as exc:
            self.log(f"ignored threat {tid}: {exc}")
            return out
        self.threats[tid] = t
        out.cot += self._send(self._uid("threat", tid), self._threat_cot(tid, t, now), now)
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
        if d.reason:
            parts.append(d.reason)
        return cot.unit_event(
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
        pts = _thin(np.asarray(path, dtype=float), self.s.route_points)
        ll = [(float(a), float(b)) for a, b in self.s.origin.to_geodetic_many(pts)]
        u = self.units.setdefault(unit, _Unit())
        if len(ll) == len(u.route) and np.allclose(ll, u.route, atol=1e-7, rtol=0.0):
            return out
        u.route = ll
        u.route_remarks = f"pfp route for {unit}: {status}, {length_m:.0f} m, {len(ll)} waypoints"
        out.cot += self._send(self._uid("route", unit), self._route_cot(unit, u, now), now)
        return out

    def _route_cot(self, unit: str, u: _Unit, now: float) -> bytes:
        uid = self._uid("route", unit)
        return cot.route_event(uid, u.route, now, self.s.stale_s, f"route {unit}", u.route_remarks)

    def tick(self, now: float) -> Outputs:
        """Held-back events whose turn came, the periodic refresh, and routes asked for too soon."""
        out = Outputs(cot=self.limiter.due(now))
        for unit, u in self.units.items():
            if u.route_pending and now - u.route_asked >= self.s.route_min_s:
                out.routes += self._ask_route(unit, now)
        if now - self._last_refresh < self.s.refresh_s:
            return out
        self._last_refresh = now
        for tid, t in self.threats.items():
            out.cot += self._send(self._uid("threat", tid), self._threat_cot(tid, t, now), now)
        for unit, u in self.units.items():
            data = None if u.direction is None else self._unit_cot(unit, u, u.direction, now)
            if data is not None:
                out.cot += self._send(self._uid("unit", unit), data, now)
            if len(u.route) >= 2:
                out.cot += self._send(self._uid("route", unit), self._route_cot(unit, u, now), now)
        return out
