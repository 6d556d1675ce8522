"""Positions for people: local metres shown as lat/lon, MGRS or metres, one format everywhere.

The planner works in metres east and north of the mission origin; people read
lat/lon or grid references.  ``Coords`` is how every human-facing output (the
plan summary and plot, fleet and inject lines, ``pfp status`` tables, the
planner's log) turns a local point into text:

* ``latlon``: ``58.41050N 15.62130E (300 m E, 260 m N)``: degrees to 5
  decimals (about a metre), hemisphere letters, then the metres from the origin;
* ``mgrs``: ``33VWE 36303 74581 (300 m E, 260 m N)``: a 1 m MGRS grid
  reference from the ``mgrs`` library (a wrapper of the NGA's GEOTRANS C code:
  small, well kept, no GDAL or PROJ to install), then the metres;
* ``metres``: ``(300.0, 260.0)``, as before, for missions without an origin.

The default is ``latlon`` when an origin is known, else ``metres``.  JSON
outputs are not shown through here: they keep both the metres and lat/lon.
``parse_point`` reads what people type back: ``X,Y`` metres, degrees with
hemisphere letters as shown above, or an MGRS grid reference.
No I/O: a pure function of the point, the origin and the style.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pfp_service.errors import InputError

if TYPE_CHECKING:
    from pfp_service.geo import Origin

__all__ = ["STYLES", "Coords", "degrees", "metres_offset", "mgrs_ref", "parse_point"]

STYLES = ("latlon", "metres", "mgrs")
Point = Sequence[float]
# 58.41050N 15.62130E, 58.4105 N, 15.6213 E, 58.4105°N 15.6213°E: what ``degrees`` shows, typed back
_DEGREES = re.compile(
    r"^\s*(\d{1,2}(?:\.\d*)?)\s*°?\s*([NS])\s*[,;\s]\s*(\d{1,3}(?:\.\d*)?)\s*°?\s*([EW])\s*$", re.I
)
# 33VWE 36303 74581, 33VWE3630374581, 33V WE 363 745: zone, band, 100 km square, 1-5 digit pairs
_MGRS = re.compile(r"^(\d{1,2})([C-HJ-NP-X])([A-HJ-NP-Z]{2})(\d*)$", re.I)


def degrees(lat: float, lon: float) -> str:
    """``58.41050N 15.62130E``: 5 decimals (about 1 m), hemisphere letters rather than signs."""
    ns = "N" if lat >= 0 else "S"
    ew = "E" if lon >= 0 else "W"
    return f"{abs(lat):.5f}{ns} {abs(lon):.5f}{ew}"


def _m(value: float) -> str:
    # a metre is what a field user reads; below 10 m a decimetre still matters (tolerances, clearances)
    return f"{abs(value):.0f}" if abs(value) >= 9.95 else f"{abs(value):.1f}"


def metres_offset(x_east_m: float, y_north_m: float) -> str:
    """``300 m E, 260 m N`` (``W`` and ``S`` for negative): the point from the mission origin."""
    if abs(x_east_m) < 0.05 and abs(y_north_m) < 0.05:
        return "the origin"
    return f"{_m(x_east_m)} m {'E' if x_east_m >= 0 else 'W'}, {_m(y_north_m)} m {'N' if y_north_m >= 0 else 'S'}"


def mgrs_ref(lat: float, lon: float) -> str:
    """``33VWE 36303 74581``: the 1 m MGRS grid reference, grid square, easting and northing apart."""
    import mgrs

    raw = str(mgrs.MGRS().toMGRS(lat, lon, MGRSPrecision=5))
    head, digits = raw[:-10], raw[-10:]
    return f"{head} {digits[:5]} {digits[5:]}"


@functools.lru_cache(maxsize=4096)
def _geodetic_cm(origin: Origin, x_cm: int, y_cm: int) -> tuple[float, float]:
    """``origin.to_geodetic`` of a point given to the centimetre (the text shows about a metre).

    One point costs pymap3d's fixed overhead (a few hundred µs on a loaded machine): a
    planner logging the same goal for a platoon, or a parked unit going stale, pays it once.
    """
    return origin.to_geodetic(x_cm / 100.0, y_cm / 100.0)


@dataclass(frozen=True)
class Coords:
    """How positions are shown: a style from ``STYLES`` and the mission origin (``None``: metres only).

    Build one with ``Coords.choose``; ``point`` and ``points`` format local metres.
    """

    style: str = "metres"
    origin: Origin | None = None

    @classmethod
    def choose(cls, flag: str | None, origin: Origin | None, *, strict: bool = True) -> Coords:
        """The ``--coords`` choice: ``flag`` if given, else ``latlon`` with an origin and ``metres`` without.

        Args:
            flag: ``--coords``, or ``None`` for the default.
            origin: the mission origin, when known.
            strict: refuse lat/lon or MGRS without an origin; when not strict (the origin
                is learnt at run time and may be missing), fall back to metres.

        Raises:
            InputError: at ``--coords``, for an unknown style, or a geodetic style without an origin.
        """
        if flag is not None and flag not in STYLES:
            raise InputError("--coords", f"expected one of {', '.join(STYLES)}, got {flag!r}")
        style = flag or ("latlon" if origin is not None else "metres")
        if style != "metres" and origin is None:
            if strict:
                raise InputError("--coords", f"{style} needs a mission origin ({{lat, lon}}); none is set")
            style = "metres"
        return cls(style, origin if style != "metres" else None)

    @property
    def geodetic(self) -> bool:
        """Whether points are shown on the earth (lat/lon or MGRS) rather than as bare metres."""
        return self.origin is not None and self.style != "metres"

    def point(self, p: Point, *, offset: bool = True, digits: int = 1) -> str:
        """One local point ``(x_east_m, y_north_m)`` as text.

        Args:
            p: the point in metres from the origin.
            offset: with a geodetic style, add the metres from the origin in brackets.
            digits: decimals of the bare metres style.
        """
        return self.points([p], offset=offset, digits=digits)[0]

    def points(self, ps: Iterable[Point], *, offset: bool = True, digits: int = 1) -> list[str]:
        """``point`` of each, with one vectorised conversion (a status table of 1,000 units)."""
        pts = [(float(p[0]), float(p[1])) for p in ps]
        if self.origin is None or self.style == "metres":
            return [f"({x:.{digits}f}, {y:.{digits}f})" for x, y in pts]
        if not pts:
            return []
        if len(pts) == 1:  # a log line: the same points recur (a platoon's goal, a parked unit)
            ll = [_geodetic_cm(self.origin, round(pts[0][0] * 100), round(pts[0][1] * 100))]
        else:
            import numpy as np

            ll = self.origin.to_geodetic_many(np.array(pts, dtype=float)).tolist()
        show = degrees if self.style == "latlon" else mgrs_ref
        out = []
        for (x, y), (lat, lon) in zip(pts, ll):
            text = show(lat, lon)
            out.append(f"{text} ({metres_offset(x, y)})" if offset else text)
        return out

    def latlon(self, p: Point) -> tuple[float, float] | None:
        """``(lat, lon)`` of a local point, or ``None`` without an origin."""
        return None if self.origin is None else self.origin.to_geodetic(float(p[0]), float(p[1]))


def parse_point(text: str, origin: Origin | None) -> tuple[float, float] | str:
    """What a person typed, as local metres ``(x_east, y_north)``, or the reason it is not a point.

    ``X,Y`` is metres from the origin; ``58.4105N 15.6213E`` (hemisphere letters, as ``degrees``
    shows them: bare ``LAT,LON`` would read as metres) and an MGRS grid reference
    (``33VWE 36303 74581``, any precision, spaces anywhere) need ``origin``.
    """
    t = text.strip()
    if m := _DEGREES.match(t):
        lat = float(m[1]) * (1 if m[2].upper() == "N" else -1)
        lon = float(m[3]) * (1 if m[4].upper() == "E" else -1)
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            return f"not a latitude and longitude: {text!r}"
        return _local(origin, lat, lon, text)
    squeezed = re.sub(r"\s+", "", t).upper()
    if (m := _MGRS.match(squeezed)) and len(m[4]) % 2 == 0 and len(m[4]) <= 10:
        import mgrs

        try:
            lat, lon = mgrs.MGRS().toLatLon(squeezed)
        except Exception as exc:  # the library's own reason (a square not in that zone, ...)
            return f"not an MGRS grid reference: {text!r} ({exc})"
        return _local(origin, float(lat), float(lon), text)
    parts = t.replace(" ", "").split(",")
    try:
        x, y = (float(v) for v in parts)
    except ValueError:
        return f"expected X,Y in metres, 58.41N 15.62E or an MGRS reference, got {text!r}"
    if not (math.isfinite(x) and math.isfinite(y)):
        return f"expected finite numbers, got {text!r}"
    return x, y


def _local(origin: Origin | None, lat: float, lon: float, text: str) -> tuple[float, float] | str:
    if origin is None:
        return f"{text.strip()!r} needs the mission origin, and none is known yet: give X,Y in metres"
    x, y = origin.to_local(lat, lon)
    return float(x), float(y)
