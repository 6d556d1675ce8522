"""Geodetic coordinates: the mission origin and the one conversion between WGS-84 and planner metres.

The planner works in a local tangent plane (ENU, east-north-up) at the
mission origin: ``x`` is metres east, ``y`` metres north, the up component is
dropped.  Every position field on the wire and in files may be written as
``[x, y]`` metres or as ``{"lat": …, "lon": …}``; ``localise`` turns the second
form into the first at the edge, so the core never sees a degree.  The maths
is pymap3d's (WGS-84 ellipsoid, via ECEF); this module adds only the 2-D
projection and its exact inverse.  The inverse and a bearing's rotation, on
every tick's directions, are pymap3d's formulas written out for their cost
(tests/unit/test_geo.py checks them against pymap3d).

Accuracy.  Dropping the up component shortens a distance ``d`` from the origin
by about ``d**3 / (6 R**2)``: 1.4 cm at 15 km and 3.8 cm at 21 km, the corner
of a 30 km x 30 km area; any two points of that area keep their distance to a
few centimetres of the Karney geodesic (tests/unit/test_geo.py measures it with
geographiclib).  ``to_local`` and ``to_geodetic`` are inverses to well under a
millimetre.  A lat/lon farther than ``MAX_RANGE_M`` from the origin is refused:
the plane is no map of that.

Grid north is the origin's north.  A unit east or west of the origin sees true
north turned by the meridian convergence (about ``dlon * sin(lat)``), so
``true_bearing_deg`` re-expresses a planner vector in the unit's own ENU frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Annotated, Any

import msgspec
from msgspec import Meta

from pfp_service.errors import InputError, from_validation

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "MAX_RANGE_M",
    "POSITION_FIELDS",
    "LatLon",
    "Origin",
    "bearings_at",
    "localise",
    "localise_document",
    "lookahead_geodetic",
    "parse_origin",
    "true_bearing_deg",
]

# Farther than this the 2-D plane is off by decimetres (0.5 m at 50 km); refuse it.
MAX_RANGE_M = 50_000.0
# Keys whose value is a position, in wire messages and in scenario, team and inject files.
POSITION_FIELDS = frozenset({"position", "start", "goal", "of"})  # "of": an inject trigger's point

_A_M = 6_378_137.0  # WGS-84 semi-major axis; pymap3d's ellipsoid, named here for the Newton step's radii
_E2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563)


def _radii(sin_lat: Any) -> tuple[Any, Any]:
    """Meridian and prime-vertical radii of curvature, metres (scalars or arrays)."""
    w = (1.0 - _E2 * sin_lat * sin_lat) ** 0.5
    return _A_M * (1.0 - _E2) / w**3, _A_M / w


def _plane(p: Any, z: Any, sin_dlon: Any, cos_dlon: Any, s0: float, c0: float, n0: float) -> tuple[Any, Any]:
    """``(east, north)`` metres on the plane of the origin at latitude ``asin(s0)`` (prime-vertical radius
    ``n0``) of a point ``p`` from the earth's axis, ``z`` over the equator, ``dlon`` east of the origin: the
    ENU of ``pymap3d.geodetic2enu`` without its up, in the origin's frame directly (no ECEF difference)."""
    return p * sin_dlon, c0 * z - s0 * p * cos_dlon + s0 * c0 * n0 * _E2


class _Wgs84:
    """pymap3d's WGS-84 ``Ellipsoid``, built once (``Ellipsoid.from_name`` on every call costs)."""

    _ell: Any = None

    @classmethod
    def get(cls) -> Any:
        if cls._ell is None:
            from pymap3d.ellipsoid import Ellipsoid

            cls._ell = Ellipsoid.from_name("wgs84")
        return cls._ell


Latitude = Annotated[float, Meta(ge=-90.0, le=90.0)]
Longitude = Annotated[float, Meta(ge=-180.0, le=180.0)]
# The origin's latitude stays off the poles, where east and north are undefined.
OriginLatitude = Annotated[float, Meta(gt=-89.9, lt=89.9)]
Altitude = Annotated[float, Meta(ge=-12_000.0, le=100_000.0)]


class LatLon(msgspec.Struct, frozen=True, kw_only=True):
    """A WGS-84 position in degrees: ``{"lat": 59.33, "lon": 18.06}`` (north and east positive)."""

    lat: Latitude
    lon: Longitude


class Origin(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The mission origin: where ``[0, 0]`` lies, and the height of the local plane.

    Attributes:
        lat: latitude in degrees, within ±89.9.
        lon: longitude in degrees, -180 to 180.
        alt: height above the WGS-84 ellipsoid in metres.
    """

    lat: OriginLatitude
    lon: Longitude
    alt: Altitude = 0.0

    def to_local(self, lat: float, lon: float) -> tuple[float, float]:
        """``(x_east_m, y_north_m)`` of a WGS-84 point on the plane's height."""
        import pymap3d

        e, n, _u = pymap3d.geodetic2enu(lat, lon, self.alt, self.lat, self.lon, self.alt, _Wgs84.get())
        return float(e), float(n)

    def to_local_many(self, latlon: np.ndarray) -> np.ndarray:
        """``(n, 2)`` of ``[x_east_m, y_north_m]`` for ``(n, 2)`` of ``[lat, lon]`` degrees: ``to_local``
        over an array (a terrain's cells are placed with it)."""
        import numpy as np
        import pymap3d

        ll = np.asarray(latlon, dtype=float)
        e, n, _u = pymap3d.geodetic2enu(
            ll[:, 0], ll[:, 1], self.alt, self.lat, self.lon, self.alt, _Wgs84.get()
        )
        return np.column_stack([np.asarray(e, dtype=float), np.asarray(n, dtype=float)])

    def to_geodetic(self, x_east_m: float, y_north_m: float) -> tuple[float, float]:
        """``(lat, lon)`` in degrees: the exact inverse of ``to_local``."""
        import numpy as np

        lat, lon = self.to_geodetic_many(np.array([[x_east_m, y_north_m]], dtype=float))[0]
        return float(lat), float(lon)

    def to_geodetic_many(self, xy: np.ndarray) -> np.ndarray:
        """``(n, 2)`` of ``[lat, lon]`` degrees for ``(n, 2)`` local metres: the inverse of ``to_local``.

        Newton's method on the plane's map in closed form (``_plane``: pymap3d's
        ``geodetic2enu`` at the plane's height, its up dropped) and its exact
        Jacobian.  Two or three steps reach 1e-8 m within ``MAX_RANGE_M``
        (tests/unit/test_geo.py checks every result with pymap3d's own inverse).
        Written out, not through pymap3d, for its cost: pymap3d's three calls a
        step cost ~0.2 ms whatever the size, most of a tick's lat/lon (issue 32).
        """
        import numpy as np

        e = np.asarray(xy[:, 0], dtype=float)
        n = np.asarray(xy[:, 1], dtype=float)
        if not len(e):
            return np.zeros((0, 2))
        lat0, h = math.radians(self.lat), self.alt
        s0, c0 = math.sin(lat0), math.cos(lat0)
        m0, n0 = _radii(s0)
        lat = lat0 + n / (m0 + h)
        dlon = e / ((n0 + h) * c0)
        with np.errstate(all="ignore"):  # a point off the globe comes out NaN, as its caller expects
            for _ in range(8):
                s, c, sd, cd = np.sin(lat), np.cos(lat), np.sin(dlon), np.cos(dlon)
                meridian, vertical = _radii(s)
                p = (vertical + h) * c  # from the earth's axis
                z = (vertical * (1.0 - _E2) + h) * s  # over the equator
                at_e, at_n = _plane(p, z, sd, cd, s0, c0, n0)
                miss_e, miss_n = e - at_e, n - at_n
                if max(float(np.abs(miss_e).max()), float(np.abs(miss_n).max())) < 1e-8:
                    break
                # d(p, z)/d(lat) = (M + h) (-sin(lat), cos(lat)); d/d(dlon) turns p about the axis
                ml = meridian + h
                a, b = -ml * s * sd, p * cd  # d(e)/d(lat), d(e)/d(dlon)
                cc, d = ml * (c0 * c + s0 * s * cd), s0 * p * sd  # d(n)/d(lat), d(n)/d(dlon)
                det = a * d - b * cc
                lat = lat + (d * miss_e - b * miss_n) / det
                dlon = dlon + (a * miss_n - cc * miss_e) / det
        lon = (self.lon + np.degrees(dlon) + 180.0) % 360.0 - 180.0
        return np.column_stack([np.degrees(lat), lon])

    def localise_point(self, p: LatLon, path: str = "position") -> tuple[float, float]:
        """``to_local`` of ``p``, refusing one farther than ``MAX_RANGE_M``.

        Raises:
            InputError: at ``path``, when ``p`` is too far from the origin.
        """
        x, y = self.to_local(p.lat, p.lon)
        d = math.hypot(x, y)
        if not d <= MAX_RANGE_M:
            raise InputError(
                path,
                f"lat {p.lat:g}, lon {p.lon:g} lies {d / 1000:.0f} km from the mission origin "
                f"(at most {MAX_RANGE_M / 1000:g} km)",
            )
        return x, y


def parse_origin(text: str) -> Origin:
    """An ``Origin`` from ``"LAT,LON[,ALT]"`` or JSON ``{"lat": …, "lon": …}`` (for flags and env).

    Raises:
        InputError: at ``origin``, with the reason.
    """
    text = text.strip()
    try:
        if text.startswith("{"):
            return msgspec.json.decode(text, type=Origin)
        parts = [float(s) for s in text.split(",")]
        if len(parts) not in (2, 3):
            raise ValueError
        return msgspec.convert(dict(zip(("lat", "lon", "alt"), parts)), Origin)
    except ValueError:
        raise InputError("origin", f"expected LAT,LON[,ALT] in degrees and metres, got {text!r}") from None
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise InputError("origin", str(exc)) from exc


def _latlon(value: dict[str, Any], path: str) -> LatLon:
    try:
        return msgspec.convert(value, LatLon)
    except msgspec.ValidationError as exc:
        e = from_validation(exc)
        raise InputError(_join(path, e.path) if e.path else path, e.reason) from exc


def _join(prefix: str, key: str) -> str:
    if key.startswith("[") or not prefix:
        return prefix + key
    return f"{prefix}.{key}"


def localise(obj: Any, origin: Origin | None, path: str = "") -> Any:
    """``obj`` with every ``{"lat", "lon"}`` position replaced by ``[x, y]`` metres.

    ``obj`` is a decoded JSON or YAML document (dicts and lists).  A position
    is the value of a key in ``POSITION_FIELDS`` and each corner of ``bounds``;
    a mapping there with ``lat`` or ``lon`` is converted, anything else is left
    for the typed decoder to judge.  The input is not modified.

    Args:
        obj: the document.
        origin: the mission origin; ``None`` refuses any lat/lon.
        path: where ``obj`` sits, prefixed to error paths (``"$"`` for the wire).

    Raises:
        InputError: a lat/lon without an origin, out of range, or too far away.
    """
    if isinstance(obj, list):
        return [localise(v, origin, _join(path, f"[{i}]")) for i, v in enumerate(obj)]
    if not isinstance(obj, dict):
        return obj
    out: dict[Any, Any] = {}
    for key, value in obj.items():
        here = _join(path, str(key))
        if key in POSITION_FIELDS and _is_geodetic(value):
            out[key] = list(_to_local(value, origin, here))
        elif key == "bounds" and isinstance(value, list):
            out[key] = [
                list(_to_local(c, origin, _join(here, f"[{i}]"))) if _is_geodetic(c) else c
                for i, c in enumerate(value)
            ]
        elif isinstance(value, (dict, list)):
            out[key] = localise(value, origin, here)
        else:
            out[key] = value
    return out


def localise_document(doc: dict[str, Any]) -> dict[str, Any]:
    """A file's document with its lat/lon positions in metres from its own ``origin`` key.

    Scenario, team and inject files carry ``origin: {lat, lon, alt}`` at the top.

    Raises:
        InputError: a bad origin (at ``origin…``), or a bad or origin-less lat/lon (at its field).
    """
    raw = doc.get("origin")
    origin = None
    if raw is not None:
        try:
            origin = msgspec.convert(raw, Origin)
        except msgspec.ValidationError as exc:
            e = from_validation(exc)
            raise InputError(f"origin.{e.path}" if e.path else "origin", e.reason) from exc
    out: dict[str, Any] = localise(doc, origin)
    return out


def _is_geodetic(value: object) -> bool:
    return isinstance(value, dict) and ("lat" in value or "lon" in value)


def _to_local(value: dict[str, Any], origin: Origin | None, path: str) -> tuple[float, float]:
    p = _latlon(value, path)
    if origin is None:
        raise InputError(path, "a lat/lon position needs a mission origin ({lat, lon}); none is set")
    return origin.localise_point(p, path)


def true_bearing_deg(origin: Origin, position: tuple[float, float], vector: tuple[float, float]) -> float:
    """The compass bearing from true north, at ``position``, of a planner vector ``(dx, dy)``.

    Args:
        origin: the mission origin (the planner's grid north is north there).
        position: the unit's local position in metres.
        vector: the direction in the planner's frame; need not be unit length.

    Returns:
        Degrees clockwise from true north, in ``[0, 360)``.
    """
    lat, lon = origin.to_geodetic(*position)
    return _bearing_at(origin, lat, lon, vector)


def _bearing_at(origin: Origin, lat: float, lon: float, vector: tuple[float, float]) -> float:
    import numpy as np

    b = bearings_at(origin, np.array([lat]), np.array([lon]), np.array([vector], dtype=float))
    return float(b[0])


def bearings_at(origin: Origin, lat: np.ndarray, lon: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Degrees clockwise from true north, in ``[0, 360)``, of planner vectors ``(n, 2)`` at ``lat``, ``lon``
    (degrees, ``(n,)`` each): each vector of the origin's ENU frame, turned into the point's.

    The rotation written out (pymap3d's ``enu2uvw`` at the origin, then ``uvw2enu`` at the point:
    tests/unit/test_geo.py compares), without their cost on a tick's few points.
    """
    import numpy as np

    lat0 = math.radians(origin.lat)
    s0, c0 = math.sin(lat0), math.cos(lat0)
    phi, dlon = np.radians(lat), np.radians(lon - origin.lon)
    s, c, sd, cd = np.sin(phi), np.cos(phi), np.sin(dlon), np.cos(dlon)
    ve, vn = vectors[:, 0], vectors[:, 1]
    east = ve * cd + vn * s0 * sd
    north = vn * (s * s0 * cd + c * c0) - ve * s * sd
    b = np.degrees(np.arctan2(east, north)) % 360.0
    out: np.ndarray = np.where(b >= 360.0, 0.0, b)  # a tiny negative angle rounds to 360.0
    return out


def lookahead_geodetic(origin: Origin, points: Iterable[tuple[float, float]]) -> list[LatLon]:
    """The look-ahead points as ``LatLon``s, rounded to 1e-7 degrees (about a centimetre)."""
    import numpy as np

    pts = np.array(list(points), dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return []
    ll = round_many(origin.to_geodetic_many(pts), 7)
    return [LatLon(lat=a, lon=b) for a, b in ll]


# |x * 10**places - (k + 1/2)| below this: ``round`` itself decides (the product may be off by an ulp)
_NEAR_HALF = 1e-4


def round_many(values: np.ndarray, places: int) -> list[Any]:
    """``round(v, places)`` for each of ``values`` (nested lists, as ``tolist``): the same floats, bit for bit.

    ``round`` costs most of a look-ahead's lat/lon (a share of a wave is
    hundreds of points).  ``rint(v * 10**places) / 10**places`` is the same
    float whenever the product is not within an ulp of a half (the division
    of two exact numbers is correctly rounded, as ``round``'s decimal is), so
    only those near a half, too big or not finite go through ``round``.
    """
    import numpy as np

    v = np.asarray(values, dtype=float)
    scale = 10.0**places
    scaled = v * scale
    frac = scaled - np.floor(scaled)
    safe = (np.abs(frac - 0.5) > _NEAR_HALF) & (np.abs(scaled) < 2.0**52)  # NaN and inf: not safe
    out = np.rint(scaled) / scale
    if not safe.all():
        flat, bad = out.reshape(-1), np.flatnonzero(~safe.reshape(-1))
        flat[bad] = [round(float(x), places) for x in v.reshape(-1)[bad]]
    got: list[Any] = out.tolist()
    return got
