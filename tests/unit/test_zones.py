"""Keep-out zones: the model (against shapely), the exact segment test, the raster, and the wire form."""

from __future__ import annotations

import contextlib
import json
import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from pfp_service.core.zones import TOUCH_M, Zone, ZoneSet, track_enters
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from pfp_service.world import translate

pytestmark = pytest.mark.unit

SQUARE_WITH_HOLE = Zone.polygon(
    "pond", [(0, 0), (10, 0), (10, 10), (0, 10)], holes=[[(4, 4), (6, 4), (6, 6), (4, 6)]]
)
RING = Zone.circle("crater", (20.0, 0.0), 3.0)
THIN = Zone.polygon("wire", [(30, -50), (30.01, -50), (30.01, 50), (30, 50)])  # 1 cm wide
ZONES = ZoneSet([SQUARE_WITH_HOLE, RING, THIN])

coord = st.floats(-60.0, 60.0, allow_nan=False).map(lambda v: round(v, 6))  # GEOS misjudges subnormals


def _shapely(zone: Zone) -> shapely.Geometry:
    if zone.centre is not None:
        return shapely.Point(zone.centre).buffer(zone.radius_m, quad_segs=256)
    return shapely.Polygon(zone.shell, zone.holes)


def test_a_polygon_with_a_hole_and_a_circle() -> None:
    assert SQUARE_WITH_HOLE.contains(1, 1)
    assert not SQUARE_WITH_HOLE.contains(5, 5)  # the hole
    assert SQUARE_WITH_HOLE.contains(0, 5)  # the boundary is in the zone
    assert SQUARE_WITH_HOLE.distance(-3, 5) == pytest.approx(3.0)
    assert SQUARE_WITH_HOLE.distance(5, 5) == pytest.approx(1.0)
    assert SQUARE_WITH_HOLE.signed_distance(1, 5) == pytest.approx(-1.0)
    assert RING.contains(20, 2.9) and not RING.contains(20, 3.1)
    assert RING.signed_distance(20, 0) == pytest.approx(-3.0)
    assert ZONES.zone_at(1, 1) == "pond" and ZONES.zone_at(5, 5) == ""


@settings(max_examples=300, deadline=None)
@given(coord, coord)
def test_signed_distance_agrees_with_shapely(x: float, y: float) -> None:
    sd = ZONES.signed_distance(np.array([[x, y]]))[0]
    want = math.inf
    for z in ZONES:
        g = _shapely(z)
        d = (
            g.exterior.distance(shapely.Point(x, y))
            if z.centre is not None
            else g.boundary.distance(shapely.Point(x, y))
        )
        want = min(want, -d if g.covers(shapely.Point(x, y)) else d)
    assert sd == pytest.approx(want, abs=1e-3)  # the circle's shapely twin is a 1024-gon


@settings(max_examples=400, deadline=None)
@given(coord, coord, coord, coord)
def test_track_enters_is_exact_against_shapely(x0: float, y0: float, x1: float, y1: float) -> None:
    line = shapely.LineString([(x0, y0), (x1, y1)]) if (x0, y0) != (x1, y1) else shapely.Point(x0, y0)
    polys = [z for z in ZONES if z.centre is None]
    got = track_enters(ZoneSet(polys), [(x0, y0), (x1, y1)])
    want = [z.id for z in polys if _shapely(z).intersects(line)]
    if want:  # never a miss
        assert got in want
    elif got is not None:  # a touch GEOS rounds the other way: conservative by a hair at most
        assert _shapely(ZoneSet(polys).get(got)).distance(line) < 1e-9  # type: ignore[arg-type]


def test_a_thin_zone_is_never_stepped_over() -> None:
    assert track_enters(ZONES, [(29.0, 0.0), (31.0, 0.0)]) == "wire"
    assert track_enters(ZONES, [(29.0, 0.0), (29.99, 0.0)]) is None
    assert track_enters(ZONES, [(15.0, 10.0), (25.0, -10.0)]) == "crater"  # passes the circle's middle
    assert track_enters(ZONES, [(-5.0, 5.0), (-1.0, 5.0), (3.0, 5.0)]) == "pond"
    assert ZONES.first_hit(np.array([[-5.0, 5.0], [-1.0, 5.0], [3.0, 5.0]])) == (1, "pond")


def test_clearance_of_a_path_is_signed() -> None:
    assert ZoneSet([RING]).clearance(np.array([[10.0, 5.0], [30.0, 5.0]])) == pytest.approx(2.0, abs=1e-6)
    assert ZoneSet([RING]).clearance(np.array([[10.0, 1.0], [30.0, 1.0]])) <= 0.0
    assert ZoneSet().clearance(np.array([[0.0, 0.0]])) == math.inf


def test_the_raster_blocks_every_cell_a_zone_touches() -> None:
    h = 1.0
    grid = ZONES.raster((-60.0, -60.0), h, (121, 121))
    assert grid[90, 60]  # the 1 cm wire at x = 30 blocks its column ...
    assert not grid[88, 60] and not grid[92, 60]
    # ... so that no move between two free 8-neighbours touches a zone
    free = np.argwhere(~grid)
    rng = np.random.default_rng(7)
    for i, k in free[rng.choice(len(free), 3000)]:
        for di, dk in ((1, 0), (0, 1), (1, 1), (1, -1)):
            j, n = i + di, k + dk
            if 0 <= j < 121 and 0 <= n < 121 and not grid[j, n]:
                a = (-60.0 + i * h, -60.0 + k * h)
                b = (-60.0 + j * h, -60.0 + n * h)
                assert track_enters(ZONES, [a, b]) is None, (a, b)


@pytest.mark.parametrize(
    ("zone", "reason"),
    [
        (lambda: Zone.polygon("x", [(0, 0), (10, 10), (10, 0), (0, 10)]), "Self-intersection"),
        (lambda: Zone.polygon("x", [(0, 0), (1, 1)]), "at least 3 distinct"),
        (lambda: Zone.polygon("x", [(0, 0), (1, 1), (2, 2)]), "not a valid polygon"),
        (lambda: Zone.circle("x", (0, 0), 0.0), "radius_m must be > 0"),
        (lambda: Zone.polygon("x", [(0, 0), (1, 0), (math.nan, 1)]), "finite"),
        (lambda: Zone("x"), "needs a polygon"),
        (lambda: Zone.polygon("x", [(0, 0), (4, 0), (0, 4)], kind="go_here"), "kind must be"),
    ],
)
def test_bad_zones_are_refused_with_the_reason(zone: object, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        zone()  # type: ignore[operator]


def test_a_zone_set_refuses_a_repeated_id_and_replaces_by_id() -> None:
    with pytest.raises(ValueError, match="'crater'"):
        ZoneSet([RING, RING])
    moved = ZONES.plus([Zone.circle("crater", (-20.0, 0.0), 3.0)])
    assert moved.ids == ("pond", "wire", "crater") and moved.zone_at(-20, 0) == "crater"
    assert ZONES.plus([], replacing=["wire"]).ids == ("pond", "crater")


# -- the wire form ----------------------------------------------------------------
def test_zone_key() -> None:
    assert keys.zone("m1", "mines-3") == "mumt/m1/zone/mines-3"
    assert keys.zones("m1") == "mumt/m1/zone/*"
    assert keys.parse("mumt/m1/zone/mines-3") == keys.Key(keys.KeyKind.ZONE, "m1", "mines-3")
    with pytest.raises(InputError, match="zone"):
        keys.zone("m1", "a/b")


def test_a_zone_update_round_trips_and_becomes_the_core_zone() -> None:
    body = {"polygon": [[[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]]], "ttl_s": 60}
    z = m.decode_zone(json.dumps(body).encode())
    assert z.ttl_s == 60 and z.kind == "keep_out"
    core = translate.zone(z, "pond")
    assert core.id == "pond" and core.shell == ((0, 0), (10, 0), (10, 10), (0, 10))
    c = translate.zone(m.decode_zone(b'{"circle": {"centre": [5, 5], "radius_m": 2}}'), "c")
    assert c.centre == (5, 5) and c.radius_m == 2
    assert json.loads(m.encode(z)) == {**body, "kind": "keep_out", "circle": None}


def test_lat_lon_vertices_become_metres_from_the_origin() -> None:
    o = Origin(lat=59.0, lon=18.0)
    ring = [{"lat": 59.0, "lon": 18.0}, {"lat": 59.001, "lon": 18.0}, {"lat": 59.001, "lon": 18.002}]
    z = m.decode_zone(json.dumps({"polygon": [[*ring, ring[0]]]}).encode(), origin=o)
    assert z.polygon is not None
    (x0, y0), (_, y1) = z.polygon[0][0], z.polygon[0][1]
    assert abs(x0) < 1e-6 and abs(y0) < 1e-6 and y1 == pytest.approx(111.4, abs=0.5)
    with pytest.raises(InputError) as e:
        m.decode_zone(json.dumps({"polygon": [[*ring, ring[0]]]}).encode())
    assert e.value.path == "$.polygon[0][0]" and "origin" in e.value.reason


@pytest.mark.parametrize(
    ("body", "path", "reason"),
    [
        ({"polygon": [[[0, 0], [10, 0], [10, 10], [0, 10]]]}, "$.polygon[0]", "closed"),
        ({"polygon": [[[0, 0], [10, 10], [10, 0], [0, 10], [0, 0]]]}, "$.polygon[0]", "crosses itself"),
        ({}, "$.polygon", "exactly one"),
        ({"polygon": [[[0, 0], [1, 0], [0, 1], [0, 0]]], "circle": {"centre": [0, 0], "radius_m": 1}}, "$.polygon",
         "exactly one"),
        ({"circle": {"centre": [0, 0], "radius_m": 0}}, "$.circle.radius_m", "> 0"),
        ({"circle": {"centre": [0, 0], "radius_m": 1e9}}, "$.circle.radius_m", "<= 100000"),
        ({"circle": {"centre": [0, "x"], "radius_m": 1}}, "$.circle.centre[1]", "finite"),
        ({"polygon": [[[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]], [[20, 20], [21, 20], [21, 21], [20, 20]]]},
         "$.polygon", "Hole lies outside shell"),
        ({"polygon": [[[0, 0], [3e5, 0], [3e5, 1], [0, 0]]]}, "$.polygon[0]", "wider than"),
        ({"polygon": [[[0, 0], [1, 0], [0, 0]]]}, "$.polygon[0]", "length must be >= 4"),
        ({"polygon": [[[0, 0], [1, 0], [0, 1], [0, 0]]], "kind": "go"}, "$.kind", "keep_out"),
        ({"polygon": [[[0, 0], [1, 0], [0, 1], [0, 0]]], "ttl_s": -1}, "$.ttl_s", "> 0"),
        ({"polygon": [[{"lat": 91, "lon": 0}, [1, 0], [0, 1], [0, 0]]]}, "$.polygon[0][0].lat", "<= 90"),
    ],
)  # fmt: skip
def test_bad_zone_updates_name_the_field(body: dict[str, object], path: str, reason: str) -> None:
    with pytest.raises(InputError) as e:
        m.decode_zone(json.dumps(body).encode(), origin=Origin(lat=0.0, lon=0.0))
    assert e.value.path == path, str(e.value)
    assert reason in e.value.reason, str(e.value)


def test_vertex_count_is_bounded() -> None:
    n = m.MAX_ZONE_VERTICES + 1
    ring = [[math.cos(2 * math.pi * i / n) * 100, math.sin(2 * math.pi * i / n) * 100] for i in range(n)]
    with pytest.raises(InputError) as e:
        m.decode_zone(json.dumps({"polygon": [[*ring, ring[0]]]}).encode())
    assert e.value.path.startswith("$.polygon")
    ok = ring[: m.MAX_ZONE_VERTICES - 1]
    assert m.decode_zone(json.dumps({"polygon": [[*ok, ok[0]]]}).encode()).polygon is not None


def test_a_field_carries_its_zones() -> None:
    from pfp_service.core.threat import Threat, ThreatField

    t = Threat.from_facing((0.0, 0.0), 0.0, 2.0, 1.0, 0.0, id="a")
    bare = ThreatField([t])
    assert not bare.zones
    f = bare.with_zones(ZONES)
    assert f.zones is ZONES and f.packed is bare.packed and len(f) == 1
    assert f.plus([Threat.from_facing((5.0, 0.0), 0.0, 2.0, 1.0, 0.0, id="b")]).zones is ZONES
    assert f.with_threats([]).zones is ZONES


@pytest.mark.parametrize("seed", range(8))
def test_the_raster_is_exactly_within_its_margin(seed: int) -> None:
    """Row by row (discs, edge strips, parity fill) gives what the node-by-node distance gives."""
    rng = np.random.default_rng(seed)
    zones: list[Zone] = []
    for k in range(4):
        if rng.uniform() < 0.4:
            zones.append(Zone.circle(f"c{k}", rng.uniform(-20, 20, 2), rng.uniform(0.05, 8)))
            continue
        n = int(rng.integers(3, 12))
        ang, rad, c = np.sort(rng.uniform(0, 2 * np.pi, n)), rng.uniform(0.5, 10, n), rng.uniform(-20, 20, 2)
        shell = [(c[0] + r * math.cos(a), c[1] + r * math.sin(a)) for a, r in zip(ang, rad, strict=True)]
        with contextlib.suppress(ValueError):  # a star whose rays go back on themselves is refused
            zones.append(Zone.polygon(f"p{k}", shell))
    zones.append(SQUARE_WITH_HOLE)
    zs = ZoneSet(zones)
    h = float(rng.uniform(0.1, 2.0))
    margin = float(rng.uniform(0.0, 2.0)) * h
    shape = (int(60 / h), int(60 / h))
    got = zs.raster((-30.0, -30.0), h, shape, margin)
    gx, gy = np.meshgrid(-30.0 + h * np.arange(shape[0]), -30.0 + h * np.arange(shape[1]), indexing="ij")
    sd = zs.signed_distance(np.stack([gx.ravel(), gy.ravel()], 1)).reshape(shape)
    differ = (got != (sd <= margin)) & (np.abs(sd - margin) > 1e-9)
    assert not differ.any(), sd[differ][:5]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), margin=st.sampled_from([0.0, 0.5, 3.0, 40.0]))
def test_contains_skipping_far_zones_is_the_full_search(seed: int, margin: float) -> None:
    """``contains`` measures only zones whose box is within its margin: the same mask as measuring all."""
    rng = np.random.default_rng(seed)
    zones = []
    for k in range(int(rng.integers(1, 40))):
        x, y = rng.uniform(-200, 200, 2)
        w, h = rng.uniform(1, 30, 2)
        if k % 3 == 0:
            zones.append(Zone.circle(f"c{k}", (float(x), float(y)), float(w)))
        else:
            ring = [(x, y), (x + w, y), (x + w, y + h), (x, y + h), (x, y)]
            zones.append(Zone.polygon(f"p{k}", [(float(a), float(b)) for a, b in ring]))
    zs = ZoneSet(zones)
    pts = rng.uniform(-260, 260, (500, 2))
    full = zs.signed_distance(pts) <= max(TOUCH_M, margin)
    assert np.array_equal(zs.contains(pts, margin), full), seed
