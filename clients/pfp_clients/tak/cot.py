"""Cursor-on-Target (CoT) XML in: pure functions, no I/O, no clock (``cot_out`` builds it).

Inbound, ``read_event(bytes)`` parses one ``<event>`` (or raises ``CotError``)
and ``to_threat_change`` maps it onto the planner's world:

- a hostile ground marker (type ``a-h-G`` or below it) becomes a ``ThreatPut``:
  ``uid`` is the threat id (``threat_id``), the marker's point the position,
  ``<track course>`` the facing, ``stale - now`` the TTL (a marker the server
  replays long after it was sent keeps only what is left of its life), and the shape
  (sigmas, skew, weight) comes from ``ThreatDefaults``;
- a drawn shape (``to_zone_change``) becomes a keep-out ``ZonePut``: a freehand
  polygon ``u-d-f`` (its ``<link point>`` vertices; one marked
  ``<closed value="false"/>`` or ending away from its start with fewer than 3
  vertices is a line, not an area, and is ignored), a rectangle ``u-d-r`` (its
  four corners) or a circle ``u-d-c-c`` (the event's point and
  ``<shape><ellipse major minor>``, radii in metres; an ellipse becomes the
  circle of its larger radius, which covers it).  ``stale - now`` is the TTL;
- a delete (``t-x-d-d``) names its target in ``<link uid>`` and becomes a ``ThreatRemoved``
  (the bridge knows whether that uid was a marker or a shape);
- a device's own position report (``<takv>`` or ``<__group>`` in its detail) is
  flagged ``CotEvent.device``: a device that just joined gets the routes;
- anything else, and our own markers echoed back, map to ``None``.

Outbound, the builders of XML bytes and the rate limiter are ``cot_out``; ``iso`` is
CoT's time format, both ways.
"""

from __future__ import annotations

import hashlib
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import UTC, datetime
from xml.parsers import expat

__all__ = [
    "MAX_EVENT_BYTES",
    "MAX_UID_CHARS",
    "UID_PREFIX",
    "CotError",
    "CotEvent",
    "ThreatDefaults",
    "ThreatPut",
    "ThreatRemoved",
    "ZonePut",
    "iso",
    "read_event",
    "threat_id",
    "to_threat_change",
    "to_zone_change",
]

MAX_EVENT_BYTES = 64 * 1024
MAX_UID_CHARS = 200  # TAK's uids are a UUID or a callsign and a UUID; a tombstone file stays bounded
# Every uid this bridge sends starts so; inbound events with it are our own echo and are ignored.
UID_PREFIX = "pfp."
_ID_OK = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
SHAPE_TYPES = ("u-d-f", "u-d-r", "u-d-c-c")  # drawn shapes: a freehand polygon, a rectangle, a circle
NO_GO_REMARK = "pfp:keep_out"  # how a planner's zone is marked in TAK: its remarks start so ...
NO_GO_STROKE = -65536  # ... drawn in opaque red (ARGB 0xFFFF0000 as ATAK's signed int) ...
NO_GO_FILL = 0x60FF0000  # ... filled translucent red (ARGB 0x60FF0000)
MAX_SHAPE_POINTS = 4096  # vertices read from one drawn shape at most (a zone's bound)


class CotError(ValueError):
    """A CoT message that cannot be used: not XML, not an ``<event>``, or a field out of range."""


@dataclass(frozen=True, slots=True)
class CotEvent:
    """The parts of a CoT event this bridge reads.

    Attributes:
        uid: the event's uid.
        type: its CoT type, e.g. ``a-h-G-U-C``.
        time: when it was sent, Unix seconds (the sender's clock).
        stale: when it goes stale, Unix seconds.
        lat: latitude in degrees.
        lon: longitude in degrees.
        course_deg: ``<track course>``, true degrees, if present.
        link_uids: the ``uid`` of each ``<link>`` in ``<detail>``, in order.
        callsign: ``<contact callsign>``, if present.
        device: the detail has ``<takv>`` or ``<__group>``: a TAK device's own report.
        link_points: ``(lat, lon)`` of each ``<link point="lat,lon[,hae]">``, in order (a shape's vertices).
        closed: ``<closed value>``, if present.
        radius_m: the larger radius of ``<shape><ellipse major minor>``, if present.
    """

    uid: str
    type: str
    time: float
    stale: float
    lat: float
    lon: float
    course_deg: float | None = None
    link_uids: tuple[str, ...] = ()
    callsign: str = ""
    device: bool = False
    link_points: tuple[tuple[float, float], ...] = ()
    closed: bool | None = None
    radius_m: float | None = None


@dataclass(frozen=True, slots=True)
class ThreatDefaults:
    """The shape given to a hostile marker, which carries only a position (and maybe a course)."""

    sigma_range_m: float = 50.0
    sigma_lateral_m: float = 30.0
    skew: float = 0.0
    weight: float = 1.0
    facing_deg: float = 0.0


@dataclass(frozen=True, slots=True)
class ThreatPut:
    """Put threat ``id``: a ``ThreatUpdate`` body as a dict (position in lat/lon)."""

    id: str
    uid: str
    body: dict[str, object]


@dataclass(frozen=True, slots=True)
class ZonePut:
    """Put zone ``id``: a ``ZoneUpdate`` body as a dict (vertices or centre in lat/lon)."""

    id: str
    uid: str
    body: dict[str, object]


@dataclass(frozen=True, slots=True)
class ThreatRemoved:
    """Remove threat ``id`` (the marker ``uid`` was deleted, or went stale)."""

    id: str
    uid: str


def _time(text: str | None, what: str) -> float:
    if not text:
        raise CotError(f"{what}: missing")
    try:
        t = datetime.fromisoformat(text.strip())
    except ValueError:
        raise CotError(f"{what}: not an ISO 8601 time: {text[:40]!r}") from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    return t.timestamp()


def _number(text: str | None, what: str, lo: float, hi: float) -> float:
    try:
        v = float(text) if text is not None else math.nan
    except ValueError:
        raise CotError(f"{what}: not a number: {(text or '')[:40]!r}") from None
    if not (lo <= v <= hi):
        raise CotError(f"{what}: must be within {lo:g} to {hi:g}, got {text!r}")
    return v


def _no_dtd(*_args: object) -> int:
    raise CotError("DTDs and entities are not accepted")


def _parse(data: bytes) -> ET.Element:
    """The XML tree of ``data``, by expat with every DTD refused at its first declaration.

    CoT has no DTD.  A byte filter for ``<!DOCTYPE`` misses the same words in UTF-16 (expat reads
    its BOM); the parser sees them whatever the encoding, so no entity is ever declared and a
    reference to one (``&u;``) is an error, never an expansion.
    """
    parser = expat.ParserCreate()
    builder = ET.TreeBuilder()
    parser.StartElementHandler = builder.start
    parser.EndElementHandler = builder.end
    parser.CharacterDataHandler = builder.data
    parser.StartDoctypeDeclHandler = _no_dtd
    parser.EntityDeclHandler = _no_dtd
    parser.UnparsedEntityDeclHandler = _no_dtd
    parser.ExternalEntityRefHandler = _no_dtd
    try:
        parser.Parse(data, True)
        root = builder.close()
    except expat.ExpatError as exc:
        raise CotError(f"not XML: {exc}") from None
    except (AssertionError, IndexError):  # TreeBuilder: a document with no root element
        raise CotError("not XML: no element") from None
    return root


def read_event(data: bytes) -> CotEvent:
    """Parse one CoT ``<event>``.

    Raises:
        CotError: the reason, short enough for one log line.
    """
    if len(data) > MAX_EVENT_BYTES:
        raise CotError(f"event of {len(data)} bytes exceeds {MAX_EVENT_BYTES}")
    root = _parse(data)
    if root.tag != "event":
        raise CotError(f"expected <event>, got <{root.tag[:40]}>")
    uid, typ = root.get("uid"), root.get("type")
    if not uid or not typ:
        raise CotError("event: uid and type are required")
    if len(uid) > MAX_UID_CHARS:  # a bridge keeps uids (tombstones): each is bounded
        raise CotError(f"event: uid of {len(uid):,} characters; the limit is {MAX_UID_CHARS}")
    point = root.find("point")
    if point is None:
        raise CotError("event: <point> is required")
    detail = root.find("detail")
    course = None
    links: tuple[str, ...] = ()
    callsign = ""
    device = False
    points: list[tuple[float, float]] = []
    closed: bool | None = None
    radius: float | None = None
    if detail is not None:
        device = detail.find("takv") is not None or detail.find("__group") is not None
        track = detail.find("track")
        if track is not None and track.get("course") not in (None, ""):
            course = _number(track.get("course"), "track.course", -360.0, 360.0) % 360.0
        links = tuple(link.get("uid", "") for link in detail.findall("link"))
        if any(len(u) > MAX_UID_CHARS for u in links):  # a delete's target becomes a tombstone's uid
            raise CotError(f"link uid longer than {MAX_UID_CHARS} characters")
        contact = detail.find("contact")
        callsign = (contact.get("callsign") or "") if contact is not None else ""
        if typ in SHAPE_TYPES:
            points, closed, radius = _shape(detail)
    return CotEvent(
        uid=uid,
        type=typ,
        time=_time(root.get("time"), "event.time"),
        stale=_time(root.get("stale"), "event.stale"),
        lat=_number(point.get("lat"), "point.lat", -90.0, 90.0),
        lon=_number(point.get("lon"), "point.lon", -180.0, 180.0),
        course_deg=course,
        link_uids=links,
        callsign=callsign,
        device=device,
        link_points=tuple(points),
        closed=closed,
        radius_m=radius,
    )


def _shape(detail: ET.Element) -> tuple[list[tuple[float, float]], bool | None, float | None]:
    """A drawn shape's vertices, ``<closed>`` flag and circle radius from its ``<detail>``."""
    points: list[tuple[float, float]] = []
    for i, link in enumerate(detail.findall("link")):
        text = link.get("point")
        if text is None:
            continue
        if len(points) >= MAX_SHAPE_POINTS:
            raise CotError(f"shape: more than {MAX_SHAPE_POINTS} vertices")
        parts = text.split(",")
        if len(parts) < 2:
            raise CotError(f"link[{i}].point: expected 'lat,lon[,hae]', got {text[:40]!r}")
        points.append(
            (
                _number(parts[0], f"link[{i}].point lat", -90.0, 90.0),
                _number(parts[1], f"link[{i}].point lon", -180.0, 180.0),
            )
        )
    flag = detail.find("closed")
    closed = None if flag is None else (flag.get("value") or "").strip().lower() == "true"
    ellipse = detail.find("shape/ellipse")
    radius = None
    if ellipse is not None:
        major = _number(ellipse.get("major"), "shape.ellipse.major", 0.0, 1e6)
        minor = _number(ellipse.get("minor", ellipse.get("major")), "shape.ellipse.minor", 0.0, 1e6)
        radius = max(major, minor)
    return points, closed, radius


def threat_id(uid: str) -> str:
    """The planner's threat id for a marker ``uid``: the uid itself when it is a valid id.

    Otherwise the allowed characters of it, shortened, plus 8 hex digits of
    its SHA-1, so two uids never share an id by accident and one uid always
    maps to the same id.
    """
    if _ID_OK.match(uid):
        return uid
    clean = re.sub(r"[^A-Za-z0-9_-]", "_", uid)[:55]
    return f"{clean}-{hashlib.sha1(uid.encode()).hexdigest()[:8]}"


def _is_hostile_ground(typ: str) -> bool:
    return typ == "a-h-G" or typ.startswith("a-h-G-")


def to_threat_change(ev: CotEvent, defaults: ThreatDefaults, now: float) -> ThreatPut | ThreatRemoved | None:
    """What a CoT event means for the planner's threats, if anything, at ``now`` (Unix s).

    The TTL is ``stale - now``: a TAK server replays a kept marker with its
    first ``time``, and ``stale - time`` would give it its whole life again.
    A hostile marker already stale (``stale <= now``) is a removal.
    """
    if ev.type == "t-x-d-d":
        targets = [u for u in ev.link_uids if u and not u.startswith(UID_PREFIX)]
        return ThreatRemoved(id=threat_id(targets[0]), uid=targets[0]) if targets else None
    if ev.uid.startswith(UID_PREFIX) or not _is_hostile_ground(ev.type):
        return None
    ttl_s = ev.stale - now
    if not ttl_s > 0.0:
        return ThreatRemoved(id=threat_id(ev.uid), uid=ev.uid)
    body: dict[str, object] = {
        "position": {"lat": ev.lat, "lon": ev.lon},
        "facing_deg": defaults.facing_deg if ev.course_deg is None else ev.course_deg,
        "sigma_range": defaults.sigma_range_m,
        "sigma_lateral": defaults.sigma_lateral_m,
        "skew": defaults.skew,
        "weight": defaults.weight,
        "ttl_s": min(ttl_s, 1e9),
    }
    return ThreatPut(id=threat_id(ev.uid), uid=ev.uid, body=body)


def to_zone_change(ev: CotEvent, now: float) -> ZonePut | ThreatRemoved | None:
    """What a drawn shape means for the planner's keep-out zones, if anything, at ``now`` (Unix s).

    A shape already stale is a removal (a ``ThreatRemoved`` naming the zone
    id: the bridge deletes the zone key).  Our own shapes echoed back, lines
    (not areas) and anything but a drawn shape map to ``None``.

    Raises:
        CotError: a shape that cannot be a zone (too few vertices, no radius).
    """
    if ev.uid.startswith(UID_PREFIX) or ev.type not in SHAPE_TYPES:
        return None
    zid = threat_id(ev.uid)
    ttl_s = ev.stale - now
    if not ttl_s > 0.0:
        return ThreatRemoved(id=zid, uid=ev.uid)
    body: dict[str, object] = {"kind": "keep_out", "ttl_s": min(ttl_s, 1e9)}
    if ev.type == "u-d-c-c":
        if not ev.radius_m:
            raise CotError("u-d-c-c: a circle needs <shape><ellipse major> > 0")
        body["circle"] = {"centre": {"lat": ev.lat, "lon": ev.lon}, "radius_m": ev.radius_m}
        return ZonePut(id=zid, uid=ev.uid, body=body)
    ring = list(ev.link_points)
    ends_closed = len(ring) >= 2 and ring[0] == ring[-1]
    if ev.closed is False or (ev.type == "u-d-f" and not ends_closed and len(set(ring)) < 3):
        return None  # a line drawn, not an area
    if ends_closed:
        ring.pop()
    if len(set(ring)) < 3:
        raise CotError(f"{ev.type}: an area needs at least 3 distinct vertices, got {len(set(ring))}")
    body["polygon"] = [[{"lat": lat, "lon": lon} for lat, lon in [*ring, ring[0]]]]
    return ZonePut(id=zid, uid=ev.uid, body=body)


def iso(t: float) -> str:
    """CoT's time format: ISO 8601 UTC with milliseconds and ``Z``."""
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
