"""NMEA 0183 GGA sentences to local metres: pure functions, no I/O.

A GPS receiver speaks lines such as::

    $GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47

``parse_gga`` checks the checksum and the fields and returns a ``Fix``, or
``None`` when the receiver says it has no fix (quality 0).  Anything it
cannot trust raises ``InputError`` naming the field, so a reader can count
the rejection and carry on.  ``read_sentence`` is the same for a stream that
carries other sentences too (RMC, GSV, ...): those come back as ``IGNORED``.

``LocalFrame`` turns latitude and longitude into metres east (x) and north (y)
of an origin, the planner's frame.  It is the project's one conversion,
``pfp_service.geo.Origin`` (the WGS-84 local tangent plane, ENU, via
pymap3d), under the names this module has always used; its accuracy is
documented and tested there (centimetres over a 30 km area).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final

import msgspec

from pfp_service.errors import InputError
from pfp_service.geo import Origin

__all__ = [
    "IGNORED",
    "WGS84_A_M",
    "WGS84_E2",
    "Fix",
    "LocalFrame",
    "nmea_checksum",
    "parse_gga",
    "parse_lat_lon",
    "read_sentence",
]

# WGS-84 semi-major axis and first eccentricity squared (f = 1/298.257223563).
WGS84_A_M: Final = 6_378_137.0
WGS84_F: Final = 1.0 / 298.257223563
WGS84_E2: Final = WGS84_F * (2.0 - WGS84_F)

# NMEA 0183 caps a sentence at 82 characters; be lenient with proprietary extras.
MAX_SENTENCE_CHARS: Final = 128
IGNORED: Final = "ignored"


@dataclass(frozen=True, slots=True)
class Fix:
    """One GGA position fix.

    Attributes:
        lat_deg: latitude, degrees, north positive.
        lon_deg: longitude, degrees, east positive.
        quality: GGA fix quality (1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float, ...; never 0).
        satellites: satellites in use, if given.
        hdop: horizontal dilution of precision, if given.
        altitude_m: antenna altitude above mean sea level, if given.
        utc_s: UTC time of day of the fix in seconds, if given.
    """

    lat_deg: float
    lon_deg: float
    quality: int
    satellites: int | None = None
    hdop: float | None = None
    altitude_m: float | None = None
    utc_s: float | None = None


def nmea_checksum(body: str) -> int:
    """XOR of every character between ``$`` and ``*`` (``body`` excludes both)."""
    value = 0
    for ch in body.encode("ascii", "replace"):
        value ^= ch
    return value


def _split(line: str) -> list[str]:
    """Check framing and checksum; return the comma-separated fields (first is the address)."""
    text = line.strip()
    if len(text) > MAX_SENTENCE_CHARS:
        raise InputError("sentence", f"longer than {MAX_SENTENCE_CHARS} characters")
    if not text.startswith("$"):
        raise InputError("sentence", "does not start with '$'")
    star = text.rfind("*")
    if star < 0:
        raise InputError("checksum", "missing ('*hh' at the end)")
    body, given = text[1:star], text[star + 1 :]
    try:
        expected = int(given, 16)
    except ValueError:
        raise InputError("checksum", f"{given!r} is not two hex digits") from None
    if len(given) != 2:
        raise InputError("checksum", f"{given!r} is not two hex digits")
    actual = nmea_checksum(body)
    if actual != expected:
        raise InputError("checksum", f"computed {actual:02X}, the sentence says {expected:02X}")
    return body.split(",")


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(what, f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise InputError(what, f"expected a finite number, got {text!r}")
    return value


def _optional(text: str, what: str) -> float | None:
    return None if text == "" else _number(text, what)


def parse_lat_lon(lat: str, ns: str, lon: str, ew: str) -> tuple[float, float]:
    """Degrees from NMEA ``ddmm.mmmm,N`` and ``dddmm.mmmm,E`` fields (south and west negative).

    Raises:
        InputError: a field is malformed, minutes reach 60, or the value is out of range.
    """
    out = []
    for text, hemi, deg_digits, limit, signs, what in (
        (lat, ns, 2, 90.0, {"N": 1.0, "S": -1.0}, "latitude"),
        (lon, ew, 3, 180.0, {"E": 1.0, "W": -1.0}, "longitude"),
    ):
        if hemi not in signs:
            raise InputError(what, f"hemisphere must be one of {'/'.join(signs)}, got {hemi!r}")
        whole = text.split(".")[0]
        if len(whole) != deg_digits + 2 or not whole.isdigit():
            raise InputError(what, f"expected {'d' * deg_digits}mm.mmmm, got {text!r}")
        degrees = float(whole[:deg_digits])
        minutes = _number(text[deg_digits:], what)
        if minutes >= 60.0:
            raise InputError(what, f"minutes must be < 60, got {text!r}")
        value = degrees + minutes / 60.0
        if value > limit:
            raise InputError(what, f"must be at most {limit:g} degrees, got {text!r}")
        out.append(signs[hemi] * value)
    return out[0], out[1]


def _utc_seconds(text: str) -> float | None:
    if text == "":
        return None
    if len(text.split(".")[0]) != 6 or not text[:6].isdigit():
        raise InputError("time", f"expected hhmmss.ss, got {text!r}")
    h, m, s = int(text[:2]), int(text[2:4]), _number(text[4:], "time")
    if h > 23 or m > 59 or s >= 61.0:  # 60.x is a leap second
        raise InputError("time", f"not a time of day: {text!r}")
    return h * 3600.0 + m * 60.0 + s


def parse_gga(line: str) -> Fix | None:
    """Parse one GGA sentence (any talker: ``$GPGGA``, ``$GNGGA``, ...).

    Args:
        line: the sentence, with or without the trailing CR LF.

    Returns:
        The fix, or ``None`` when the receiver reports no fix (quality 0).

    Raises:
        InputError: bad framing or checksum, not a GGA sentence, or a bad field.
    """
    fields = _split(line)
    address = fields[0]
    if len(address) != 5 or not address.endswith("GGA"):
        raise InputError("sentence", f"not a GGA sentence: {address!r}")
    if len(fields) < 15:
        raise InputError("sentence", f"GGA has 15 fields, got {len(fields)}")
    utc_s = _utc_seconds(fields[1])
    try:
        quality = int(fields[6]) if fields[6] else 0
    except ValueError:
        raise InputError("quality", f"expected a whole number, got {fields[6]!r}") from None
    if quality == 0 or fields[2] == "" or fields[4] == "":
        return None
    lat_deg, lon_deg = parse_lat_lon(fields[2], fields[3], fields[4], fields[5])
    satellites = int(fields[7]) if fields[7].isdigit() else None
    return Fix(
        lat_deg=lat_deg,
        lon_deg=lon_deg,
        quality=quality,
        satellites=satellites,
        hdop=_optional(fields[8], "hdop"),
        altitude_m=_optional(fields[9], "altitude"),
        utc_s=utc_s,
    )


def read_sentence(line: str) -> Fix | str | None:
    """One line of a receiver's stream: a ``Fix``, ``None`` (GGA without a fix) or ``IGNORED``.

    Sentences other than GGA (RMC, GSA, GSV, ...) and blank lines are ``IGNORED``
    without checking them; a GGA sentence is checked fully.

    Raises:
        InputError: a GGA sentence that cannot be trusted, or a line that is not NMEA.
    """
    text = line.strip()
    if text == "":
        return IGNORED
    if text.startswith("$") and text[3:6] != "GGA":
        return IGNORED
    return parse_gga(text)


@dataclass(frozen=True, slots=True)
class LocalFrame:
    """A local tangent plane at ``origin``: degrees to metres east (x) and north (y).

    Attributes:
        lat0_deg: the origin's latitude, strictly between -90 and 90 (the plane needs ±89.9).
        lon0_deg: the origin's longitude, -180 to 180.
    """

    lat0_deg: float
    lon0_deg: float
    origin: Origin = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lat0_deg) and -90.0 < self.lat0_deg < 90.0):
            raise InputError("origin", f"latitude must be strictly between -90 and 90, got {self.lat0_deg}")
        if not (math.isfinite(self.lon0_deg) and -180.0 <= self.lon0_deg <= 180.0):
            raise InputError("origin", f"longitude must be within -180..180, got {self.lon0_deg}")
        try:
            origin = msgspec.convert({"lat": self.lat0_deg, "lon": self.lon0_deg}, Origin)
        except msgspec.ValidationError as exc:
            raise InputError("origin", f"latitude must be within ±89.9, got {self.lat0_deg}") from exc
        object.__setattr__(self, "origin", origin)

    @property
    def radii_m(self) -> tuple[float, float]:
        """``(M, N)``: meridian and prime vertical radii of curvature at the origin, metres.

        Metres per radian of latitude and (times ``cos(lat0)``) of longitude at the
        origin: a display's scale, not the conversion (that is ``to_local_m``).
        """
        s = math.sin(math.radians(self.lat0_deg))
        w = math.sqrt(1.0 - WGS84_E2 * s * s)
        return WGS84_A_M * (1.0 - WGS84_E2) / w**3, WGS84_A_M / w

    def to_local_m(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """``(x_east_m, y_north_m)`` of a point; longitudes wrap across the antimeridian."""
        return self.origin.to_local(lat_deg, lon_deg)

    def to_geodetic(self, x_east_m: float, y_north_m: float) -> tuple[float, float]:
        """``(lat_deg, lon_deg)`` of a local point: the inverse of ``to_local_m``."""
        return self.origin.to_geodetic(x_east_m, y_north_m)
