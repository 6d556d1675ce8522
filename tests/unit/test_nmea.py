"""NMEA GGA parsing and the local-metre frame, checked against published sentences and geodesy."""

from __future__ import annotations

import functools
import math
import operator

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pfp_clients.nmea import IGNORED, Fix, LocalFrame, nmea_checksum, parse_gga, read_sentence

from pfp_service.errors import InputError

pytestmark = pytest.mark.unit

# Published examples with their receivers' own checksums (not computed by the code under test).
CLASSIC = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"
DUBLIN = "$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76"


def signed(body: str) -> str:
    """``$body*hh`` with the checksum computed here, independently of the module."""
    return f"${body}*{functools.reduce(operator.xor, body.encode(), 0):02X}\r\n"


def test_classic_gga():
    fix = parse_gga(CLASSIC)
    assert isinstance(fix, Fix)
    assert fix.lat_deg == pytest.approx(48 + 7.038 / 60)
    assert fix.lon_deg == pytest.approx(11 + 31.0 / 60)
    assert (fix.quality, fix.satellites, fix.hdop, fix.altitude_m) == (1, 8, 0.9, 545.4)
    assert fix.utc_s == 12 * 3600 + 35 * 60 + 19


def test_western_hemisphere_and_crlf():
    fix = parse_gga(DUBLIN + "\r\n")
    assert fix is not None
    assert fix.lat_deg == pytest.approx(53 + 21.6802 / 60)
    assert fix.lon_deg == pytest.approx(-(6 + 30.3372 / 60))
    assert fix.utc_s == pytest.approx(9 * 3600 + 27 * 60 + 50)


def test_southern_and_western_hemispheres():
    fix = parse_gga(signed("GNGGA,010203.50,3351.5000,S,15112.3000,E,2,12,0.7,20.0,M,22.0,M,,"))
    assert fix is not None
    assert fix.lat_deg == pytest.approx(-(33 + 51.5 / 60))
    assert fix.lon_deg == pytest.approx(151 + 12.3 / 60)
    assert fix.quality == 2
    sw = parse_gga(signed("GPGGA,,2254.0000,S,04312.0000,W,1,05,1.5,,M,,M,,"))
    assert sw is not None
    assert sw.lat_deg == pytest.approx(-(22 + 54 / 60))
    assert sw.lon_deg == pytest.approx(-(43 + 12 / 60))
    assert sw.utc_s is None and sw.altitude_m is None


def test_checksum_matches_published():
    assert nmea_checksum(CLASSIC[1 : CLASSIC.index("*")]) == 0x47


@pytest.mark.parametrize(
    ("line", "path"),
    [
        (CLASSIC.replace("*47", "*48"), "checksum"),
        (CLASSIC.replace("4807.038", "4807.039"), "checksum"),  # corrupted in transit
        (CLASSIC[: CLASSIC.index("*")], "checksum"),
        (CLASSIC.replace("*47", "*G7"), "checksum"),
        ("GPGGA,123519", "sentence"),
        ("$" + "A" * 200 + "*00", "sentence"),
        (signed("GPGGA,123519,4807.038,N"), "sentence"),
        (signed("GPGGA,123519,4867.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"), "latitude"),
        (signed("GPGGA,123519,4807.038,X,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"), "latitude"),
        (signed("GPGGA,123519,4807.038,N,1131.000,E,1,08,0.9,545.4,M,46.9,M,,"), "longitude"),
        (signed("GPGGA,123519,4807.038,N,18131.000,E,1,08,0.9,545.4,M,46.9,M,,"), "longitude"),
        (signed("GPGGA,123519,4807.038,N,01131.000,E,x,08,0.9,545.4,M,46.9,M,,"), "quality"),
        (signed("GPGGA,253519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"), "time"),
        (signed("GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W"), "sentence"),
    ],
)
def test_bad_sentences_are_rejected_with_the_field(line, path):
    with pytest.raises(InputError) as err:
        parse_gga(line)
    assert err.value.path == path


def test_no_fix_is_none_not_an_error():
    assert parse_gga(signed("GPGGA,123519,,,,,0,00,99.9,,M,,M,,")) is None
    # quality 0 with stale coordinates still means "do not trust this position"
    assert parse_gga(signed("GPGGA,123519,4807.038,N,01131.000,E,0,00,99.9,,M,,M,,")) is None


def test_stream_ignores_other_sentences_and_survives_garbage():
    lines = [
        "",
        signed("GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W"),
        "\x00\xffgarbage",
        CLASSIC.replace("*47", "*00"),
        CLASSIC,
    ]
    results, errors = [], []
    for line in lines:
        try:
            results.append(read_sentence(line))
        except InputError as exc:
            errors.append(exc.path)
    assert results[:2] == [IGNORED, IGNORED]
    assert isinstance(results[-1], Fix)
    assert errors == ["sentence", "checksum"]


# -- the local frame ------------------------------------------------------------------
# Lengths of one degree on WGS-84 from the standard table (latitude: meridian arc, longitude: parallel).
@pytest.mark.parametrize(
    ("lat0", "deg_lat_m", "deg_lon_m"),
    [(0.0, 110_574.0, 111_320.0), (45.0, 111_132.0, 78_847.0), (60.0, 111_412.0, 55_800.0)],
)
def test_metres_per_degree_match_the_ellipsoid(lat0, deg_lat_m, deg_lon_m):
    frame = LocalFrame(lat0, 10.0)
    x, y = frame.to_local_m(lat0 + 0.001, 10.0)
    assert x == pytest.approx(0.0, abs=1e-9)
    assert y == pytest.approx(deg_lat_m / 1000, abs=0.01)
    x, y = frame.to_local_m(lat0, 10.001)
    # a parallel is no straight line on the tangent plane: it bends north by x**2 tan(lat0) / (2 N)
    assert y == pytest.approx(x**2 * math.tan(math.radians(lat0)) / (2 * frame.radii_m[1]), abs=1e-6)
    assert x == pytest.approx(deg_lon_m / 1000, abs=0.01)


def test_a_thousandth_of_a_degree_of_latitude_is_about_111_m():
    for lat0 in (-60.0, -10.0, 0.0, 33.0, 48.1, 70.0):
        _, y = LocalFrame(lat0, 0.0).to_local_m(lat0 + 0.001, 0.0)
        assert y == pytest.approx(111.2, abs=0.7)


def _vincenty_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Geodesic distance on WGS-84 (Vincenty's inverse formula), an independent reference."""
    a, f = 6378137.0, 1 / 298.257223563
    b = (1 - f) * a
    u1, u2 = (
        math.atan((1 - f) * math.tan(math.radians(lat1))),
        math.atan((1 - f) * math.tan(math.radians(lat2))),
    )
    big_l = math.radians(lon2 - lon1)
    lam = big_l
    for _ in range(200):
        sl, cl = math.sin(lam), math.cos(lam)
        ss = math.hypot(math.cos(u2) * sl, math.cos(u1) * math.sin(u2) - math.sin(u1) * math.cos(u2) * cl)
        cs = math.sin(u1) * math.sin(u2) + math.cos(u1) * math.cos(u2) * cl
        sigma = math.atan2(ss, cs)
        sa = math.cos(u1) * math.cos(u2) * sl / ss
        c2a = 1 - sa * sa
        c2m = cs - 2 * math.sin(u1) * math.sin(u2) / c2a
        c = f / 16 * c2a * (4 + f * (4 - 3 * c2a))
        prev = lam
        lam = big_l + (1 - c) * f * sa * (sigma + c * ss * (c2m + c * cs * (-1 + 2 * c2m * c2m)))
        if abs(lam - prev) < 1e-13:
            break
    u_sq = c2a * (a * a - b * b) / (b * b)
    k1 = 1 + u_sq / 16384 * (4096 + u_sq * (-768 + u_sq * (320 - 175 * u_sq)))
    k2 = u_sq / 1024 * (256 + u_sq * (-128 + u_sq * (74 - 47 * u_sq)))
    ds = (
        k2
        * ss
        * (c2m + k2 / 4 * (cs * (-1 + 2 * c2m**2) - k2 / 6 * c2m * (-3 + 4 * ss**2) * (-3 + 4 * c2m**2)))
    )
    return b * k1 * (sigma - ds)


@pytest.mark.parametrize(("lat0", "lon0"), [(48.117, 11.517), (-33.86, 151.2), (53.36, -6.5), (1.0, 179.99)])
def test_distances_within_half_a_permille_out_to_10_km(lat0, lon0):
    frame = LocalFrame(lat0, lon0)
    for bearing_deg in range(0, 360, 30):
        for dist_m in (50.0, 1000.0, 10_000.0):
            b = math.radians(bearing_deg)
            lat, lon = frame.to_geodetic(dist_m * math.sin(b), dist_m * math.cos(b))
            true_m = _vincenty_m(lat0, lon0, lat, lon)
            assert true_m == pytest.approx(dist_m, rel=5e-4), (bearing_deg, dist_m)


@given(
    st.floats(-80, 80),
    st.floats(-180, 180),
    st.floats(-5000, 5000),
    st.floats(-5000, 5000),
)
def test_round_trip(lat0, lon0, x, y):
    frame = LocalFrame(lat0, lon0)
    lat, lon = frame.to_geodetic(x, y)
    x2, y2 = frame.to_local_m(lat, lon)
    assert (x2, y2) == pytest.approx((x, y), abs=1e-6)


def test_bad_origin():
    for lat, lon in ((90.0, 0.0), (-91.0, 0.0), (0.0, 181.0), (math.nan, 0.0)):
        with pytest.raises(InputError) as err:
            LocalFrame(lat, lon)
        assert err.value.path == "origin"
