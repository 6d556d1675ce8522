"""Cursor-on-Target (CoT) XML out: builders of events and a rate limiter, pure, no I/O, no clock.

Outbound, the builders return XML bytes: ``zone_event`` (a planner's zone as
a no-go shape: ``u-d-f`` polygon or ``u-d-c-c`` circle, red outline
``NO_GO_STROKE``, translucent red fill ``NO_GO_FILL``, remarks starting
``pfp:keep_out``), ``threat_event`` (``a-h-G``),
``unit_event`` (``a-f-G-U-C`` manned, ``a-f-G-E-V`` unmanned, the direction
as ``<track course>``, the status in ``<remarks>``), ``route_event`` (``b-m-r``
with ordered ``<link>`` waypoints ``b-m-p-w`` at the ends and control points
``b-m-p-c`` between) and ``delete_event``.  Points carry full float precision
(pytak's helpers round to 4 decimals, about 11 m) and a height ``hae``, the
mission origin's altitude, as the planner works in the plane.

``RateLimiter`` holds back a uid's events to one per ``interval_s`` and sends
the latest when its turn comes, so nothing is lost but the intermediate ones.

Apart from reading CoT (``cot``), whose names and constants these share.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field

from pfp_clients.tak.cot import NO_GO_FILL, NO_GO_STROKE, iso

__all__ = ["RateLimiter", "delete_event", "route_event", "threat_event", "unit_event", "zone_event"]

_UNKNOWN_ERROR = "9999999.0"  # CoT's "unknown" circular and linear error


def _event(
    uid: str,
    typ: str,
    lat: float,
    lon: float,
    now: float,
    stale_s: float,
    how: str = "m-g",
    hae: float = 0.0,
) -> ET.Element:
    ev = ET.Element(
        "event",
        {
            "version": "2.0",
            "uid": uid,
            "type": typ,
            "how": how,
            "time": iso(now),
            "start": iso(now),
            "stale": iso(now + stale_s),
        },
    )
    # repr() keeps every digit: the full double, not pytak's 4 decimals
    ET.SubElement(
        ev,
        "point",
        {
            "lat": repr(float(lat)),
            "lon": repr(float(lon)),
            "hae": repr(float(hae)),
            "ce": _UNKNOWN_ERROR,
            "le": _UNKNOWN_ERROR,
        },
    )
    return ev


def _bytes(ev: ET.Element) -> bytes:
    return ET.tostring(ev, encoding="utf-8", xml_declaration=True)


def threat_event(
    uid: str,
    lat: float,
    lon: float,
    now: float,
    stale_s: float,
    facing_deg: float,
    remarks: str,
    callsign: str,
    hae: float = 0.0,
) -> bytes:
    """A hostile ground marker (``a-h-G``) for one of the planner's threats."""
    ev = _event(uid, "a-h-G", lat, lon, now, stale_s, how="h-e", hae=hae)
    d = ET.SubElement(ev, "detail")
    ET.SubElement(d, "track", {"course": repr(float(facing_deg) % 360.0), "speed": "0.0"})
    ET.SubElement(d, "contact", {"callsign": callsign})
    ET.SubElement(d, "remarks").text = remarks
    return _bytes(ev)


def unit_event(
    uid: str,
    manned: bool,
    lat: float,
    lon: float,
    now: float,
    stale_s: float,
    course_deg: float | None,
    speed_mps: float,
    remarks: str,
    callsign: str,
    hae: float = 0.0,
) -> bytes:
    """A unit's friendly marker: ``a-f-G-U-C`` manned, ``a-f-G-E-V`` unmanned; its direction as the course."""
    ev = _event(uid, "a-f-G-U-C" if manned else "a-f-G-E-V", lat, lon, now, stale_s, hae=hae)
    d = ET.SubElement(ev, "detail")
    if course_deg is not None:
        ET.SubElement(
            d, "track", {"course": repr(float(course_deg) % 360.0), "speed": repr(float(speed_mps))}
        )
    ET.SubElement(d, "contact", {"callsign": callsign})
    ET.SubElement(d, "remarks").text = remarks
    return _bytes(ev)


def route_event(
    uid: str,
    waypoints: Sequence[tuple[float, float]],
    now: float,
    stale_s: float,
    callsign: str,
    remarks: str,
    hae: float | Sequence[float] = 0.0,
) -> bytes:
    """A route (``b-m-r``): ``waypoints`` as ``(lat, lon)`` in order, each a ``<link>``, at ``hae``
    (one height for all, or one per waypoint).

    Raises:
        ValueError: fewer than two waypoints, or not one height per waypoint.
    """
    if len(waypoints) < 2:
        raise ValueError("route_event: a route needs at least two waypoints")
    heights = [float(hae)] * len(waypoints) if isinstance(hae, int | float) else [float(h) for h in hae]
    if len(heights) != len(waypoints):
        raise ValueError(f"route_event: {len(heights)} heights for {len(waypoints)} waypoints")
    lat0, lon0 = waypoints[0]
    ev = _event(uid, "b-m-r", lat0, lon0, now, stale_s, how="h-e", hae=heights[0])
    d = ET.SubElement(ev, "detail")
    last = len(waypoints) - 1
    for i, ((lat, lon), h) in enumerate(zip(waypoints, heights)):
        end = i in (0, last)
        ET.SubElement(
            d,
            "link",
            {
                "uid": f"{uid}.{i}",
                "callsign": ("start" if i == 0 else "goal") if end else f"CP{i}",
                "type": "b-m-p-w" if end else "b-m-p-c",
                "point": f"{float(lat)!r},{float(lon)!r},{h!r}",
                "remarks": "",
                "relation": "c",
            },
        )
    ET.SubElement(
        d,
        "link_attr",
        {
            "planningmethod": "Infil",
            "color": "-1",
            "method": "Driving",
            "prefix": "CP",
            "type": "Vehicle",
            "stroke": "3",
            "direction": "Infil",
            "routetype": "Primary",
            "order": "Ascending Check Points",
        },
    )
    ET.SubElement(d, "contact", {"callsign": callsign})
    ET.SubElement(d, "remarks").text = remarks
    return _bytes(ev)


def zone_event(
    uid: str,
    ring: Sequence[tuple[float, float]] | None,
    centre: tuple[float, float],
    radius_m: float | None,
    now: float,
    stale_s: float,
    callsign: str,
    remarks: str,
    hae: float = 0.0,
) -> bytes:
    """A planner's keep-out zone as a no-go shape: a polygon ``u-d-f`` (``ring``: ``(lat, lon)``
    vertices, not repeated at the end) or a circle ``u-d-c-c`` (``radius_m`` about ``centre``).

    Marked as no-go: red outline (``NO_GO_STROKE``), translucent red fill
    (``NO_GO_FILL``), and ``remarks`` that should start with ``NO_GO_REMARK``.
    """
    circle = radius_m is not None
    lat0, lon0 = centre
    ev = _event(uid, "u-d-c-c" if circle else "u-d-f", lat0, lon0, now, stale_s, how="h-e", hae=hae)
    d = ET.SubElement(ev, "detail")
    if circle:
        shape = ET.SubElement(d, "shape")
        r = repr(float(radius_m))  # type: ignore[arg-type]
        ET.SubElement(shape, "ellipse", {"major": r, "minor": r, "angle": "360"})
    else:
        pts = list(ring or ())
        for lat, lon in [*pts, pts[0]]:
            ET.SubElement(d, "link", {"point": f"{float(lat)!r},{float(lon)!r},{float(hae)!r}"})
        ET.SubElement(d, "closed", {"value": "true"})
    ET.SubElement(d, "strokeColor", {"value": str(NO_GO_STROKE)})
    ET.SubElement(d, "strokeWeight", {"value": "3.0"})
    ET.SubElement(d, "fillColor", {"value": str(NO_GO_FILL)})
    ET.SubElement(d, "labels_on", {"value": "true"})
    ET.SubElement(d, "contact", {"callsign": callsign})
    ET.SubElement(d, "remarks").text = remarks
    return _bytes(ev)


def delete_event(
    uid: str, target_uid: str, target_type: str, lat: float, lon: float, now: float, hae: float = 0.0
) -> bytes:
    """``t-x-d-d``: tell TAK clients to remove the marker ``target_uid``."""
    ev = _event(uid, "t-x-d-d", lat, lon, now, 20.0, how="h-g-i-g-o", hae=hae)
    d = ET.SubElement(ev, "detail")
    ET.SubElement(d, "link", {"uid": target_uid, "relation": "none", "type": target_type})
    ET.SubElement(d, "__forcedelete")
    return _bytes(ev)


@dataclass
class RateLimiter:
    """At most one event per uid per ``interval_s``; a held-back event is replaced by a newer one.

    ``offer(uid, data, now)`` returns what may go now (``[]`` or ``[data]``);
    ``due(now)`` returns the held-back events whose turn has come.
    """

    interval_s: float
    _last: dict[str, float] = field(default_factory=dict)
    _held: dict[str, bytes] = field(default_factory=dict)

    def offer(self, uid: str, data: bytes, now: float) -> list[bytes]:
        last = self._last.get(uid)
        if last is None or now - last >= self.interval_s:
            self._last[uid] = now
            self._held.pop(uid, None)
            return [data]
        self._held[uid] = data
        return []

    def due(self, now: float) -> list[bytes]:
        out = []
        for uid in [u for u in self._held if now - self._last[u] >= self.interval_s]:
            out.append(self._held.pop(uid))
            self._last[uid] = now
        return out

    @property
    def held(self) -> int:
        return len(self._held)
