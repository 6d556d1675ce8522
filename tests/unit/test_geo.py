"""Geodetic positions: the ENU plane against Karney's geodesics, lat/lon on the wire, directions' bearings."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from geographiclib.geodesic import Geodesic
from hypothesis import given, settings
from hypothesis import strategies as st

from pfp_service import geo
from pfp_service.errors import InputError
from pfp_service.geo import LatLon, Origin
from pfp_service.wire import geodetic
from pfp_service.wire import messages as m

WGS84 = Geodesic.WGS84
ORIGINS = [
    Origin(lat=59.3293, lon=18.0686),
    Origin(lat=-33.86, lon=151.21, alt=40.0),
    Origin(lat=0.5, lon=179.9),
]


def _walk(o: Origin, x: float, y: float) -> tuple[float, float]:
    """Karney's direct problem from the origin: the lat/lon ``hypot(x, y)`` metres along bearing atan2(x, y)."""
    g = WGS84.Direct(o.lat, o.lon, math.degrees(math.atan2(x, y)), math.hypot(x, y))
    return g["lat2"], g["lon2"]


@pytest.mark.unit
@pytest.mark.parametrize("o", ORIGINS)
def test_round_trip_is_exact_to_a_tenth_of_a_millimetre(o):
    rng = np.random.default_rng(7)
    xy = rng.uniform(-25_000, 25_000, size=(200, 2))
    ll = o.to_geodetic_many(xy)
    back = np.array([o.to_local(a, b) for a, b in ll])
    assert np.max(np.abs(back - xy)) < 1e-4


@pytest.mark.unit
@pytest.mark.parametrize("o", ORIGINS)
def test_distances_in_a_30_km_area_match_karney_to_centimetres(o):
    """The documented accuracy: any two points of a 30 km x 30 km area keep their geodesic distance to < 10 cm."""
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(300):
        (x1, y1), (x2, y2) = rng.uniform(-15_000, 15_000, size=(2, 2))
        (a1, b1), (a2, b2) = o.to_geodetic_many(np.array([[x1, y1], [x2, y2]]))
        # the plane lies at the origin's height: distances there are longer by alt / R than on the ellipsoid
        s12 = WGS84.Inverse(a1, b1, a2, b2)["s12"] * (1.0 + o.alt / 6_371_000.0)
        worst = max(worst, abs(math.hypot(x2 - x1, y2 - y1) - s12))
    assert worst < 0.10, worst
    # from the origin the error is the projection's d**3 / (6 R**2): 1.4 cm at 15 km
    lat, lon = _walk(o, 15_000.0, 0.0)
    x, y = o.to_local(lat, lon)
    assert 0.005 < 15_000.0 * (1.0 + o.alt / 6_371_000.0) - math.hypot(x, y) < 0.03


@pytest.mark.unit
@settings(max_examples=50, deadline=None)
@given(
    st.floats(-15_000, 15_000),
    st.floats(-15_000, 15_000),
    st.floats(0, 359.9),
)
def test_true_bearing_matches_the_geodesic_azimuth(x, y, heading):
    """A planner vector re-expressed at the unit is the azimuth of the short geodesic along it."""
    o = ORIGINS[0]
    dx, dy = math.sin(math.radians(heading)), math.cos(math.radians(heading))
    lat1, lon1 = o.to_geodetic(x, y)
    lat2, lon2 = o.to_geodetic(x + dx, y + dy)  # one metre along the vector
    azi = WGS84.Inverse(lat1, lon1, lat2, lon2)["azi1"] % 360.0
    got = geo.true_bearing_deg(o, (x, y), (dx, dy))
    assert abs((got - azi + 180.0) % 360.0 - 180.0) < 0.01


@pytest.mark.unit
def test_true_bearing_turns_by_the_meridian_convergence():
    o = ORIGINS[0]
    x = 15_000.0  # east of the origin, north of the equator: grid north lies east of true north
    _lat, lon = o.to_geodetic(x, 0.0)
    convergence = (lon - o.lon) * math.sin(math.radians(o.lat))
    assert 0.2 < convergence < 0.25
    assert abs(geo.true_bearing_deg(o, (x, 0.0), (0.0, 1.0)) - convergence) < 0.001


@pytest.mark.unit
def test_localise_converts_positions_and_names_their_paths():
    o = ORIGINS[0]
    lat, lon = o.to_geodetic(100.0, -50.0)
    doc = {
        "start": {"lat": lat, "lon": lon},
        "goal": [1.0, 2.0],
        "bounds": [{"lat": lat, "lon": lon}, [500.0, 500.0]],
        "threats": [{"position": {"lat": lat, "lon": lon}, "alpha": [1.0, 0.0]}],
    }
    out = geo.localise(doc, o)
    assert np.allclose(out["start"], [100.0, -50.0], atol=1e-6)
    assert out["goal"] == [1.0, 2.0] and out["bounds"][1] == [500.0, 500.0]
    assert np.allclose(out["bounds"][0], [100.0, -50.0], atol=1e-6)
    assert np.allclose(out["threats"][0]["position"], [100.0, -50.0], atol=1e-6)
    assert out["threats"][0]["alpha"] == [1.0, 0.0]
    assert doc["start"] == {"lat": lat, "lon": lon}  # not modified
    with pytest.raises(InputError) as e:
        geo.localise(doc, None)
    assert e.value.path == "start" and "origin" in e.value.reason
    with pytest.raises(InputError) as e:
        geo.localise({"threats": [{"position": {"lat": 95, "lon": 0}}]}, o, "$")
    assert e.value.path == "$.threats[0].position.lat" and "<= 90" in e.value.reason
    with pytest.raises(InputError) as e:
        geo.localise({"goal": {"lat": lat}}, o)
    assert e.value.path == "goal.lon" and "is required" in e.value.reason
    with pytest.raises(InputError) as e:
        geo.localise({"goal": {"lat": o.lat + 1.0, "lon": o.lon}}, o)
    assert e.value.path == "goal" and "111 km from the mission origin" in e.value.reason


@pytest.mark.unit
@pytest.mark.parametrize(
    ("text", "want"),
    [
        ("59.5,18.25", Origin(lat=59.5, lon=18.25)),
        (' {"lat": 1, "lon": 2, "alt": 3} ', Origin(lat=1, lon=2, alt=3)),
    ],
)
def test_parse_origin(text, want):
    assert geo.parse_origin(text) == want


@pytest.mark.unit
@pytest.mark.parametrize("text", ["59.5", "a,b", "95,0", '{"lat": 1}', "1,2,3,4"])
def test_parse_origin_refuses(text):
    with pytest.raises(InputError) as e:
        geo.parse_origin(text)
    assert e.value.path == "origin"


# -- on the wire ----------------------------------------------------------------
@pytest.mark.unit
def test_a_lat_lon_message_decodes_to_the_same_metres():
    o = ORIGINS[0]
    lat, lon = o.to_geodetic(120.5, 80.25)
    for decode, body in (
        (m.decode_unit_state, {"position": [120.5, 80.25], "seq": 3}),
        (m.decode_goal, {"position": [120.5, 80.25], "tolerance": 1.0}),
        (m.decode_threat, {"position": [120.5, 80.25], "sigma_range": 5, "sigma_lateral": 3}),
    ):
        metres = decode(json.dumps(body).encode())
        geodetic = decode(json.dumps({**body, "position": {"lat": lat, "lon": lon}}).encode(), origin=o)
        assert type(geodetic) is type(metres)
        assert np.allclose(geodetic.position, metres.position, atol=1e-6)
    req = m.decode_preview_request(
        json.dumps(
            {
                "start": {"lat": lat, "lon": lon},
                "goal": [0, 0],
                "threats": [
                    {"id": "a", "position": {"lat": lat, "lon": lon}, "sigma_range": 2, "sigma_lateral": 2}
                ],
            }
        ).encode(),
        origin=o,
    )
    assert np.allclose(req.start, (120.5, 80.25), atol=1e-6)
    assert np.allclose(req.threats[0].position, (120.5, 80.25), atol=1e-6)


@pytest.mark.unit
@pytest.mark.parametrize(
    ("body", "origin", "path", "fragment"),
    [
        ({"position": {"lat": 59.33, "lon": 18.07}}, None, "$.position", "needs a mission origin"),
        ({"position": {"lat": 91, "lon": 18.07}}, ORIGINS[0], "$.position.lat", "must be <= 90"),
        ({"position": {"lat": "x", "lon": 18.07}}, ORIGINS[0], "$.position.lat", "expected float"),
        ({"position": {"lat": 60.5, "lon": 18.07}}, ORIGINS[0], "$.position", "from the mission origin"),
        ({"position": [0, 0], "seq": "lat"}, ORIGINS[0], "$.seq", "expected int"),
    ],
)
def test_bad_lat_lon_is_rejected_with_its_path(body, origin, path, fragment):
    with pytest.raises(InputError) as e:
        m.decode_unit_state(json.dumps(body).encode(), origin=origin)
    assert e.value.path == path and fragment in e.value.reason, str(e.value)


@pytest.mark.unit
def test_mission_bounds_apply_after_conversion():
    o = ORIGINS[0]
    lat, lon = o.to_geodetic(150.0, 0.0)
    with pytest.raises(InputError) as e:
        m.decode_goal(
            json.dumps({"position": {"lat": lat, "lon": lon}}).encode(), bounds=((0, 0), (100, 100)), origin=o
        )
    assert e.value.path == "$.position" and "outside the mission bounds" in e.value.reason


@pytest.mark.unit
def test_with_geodetic_fills_bearing_and_lat_lon_lookahead():
    o = ORIGINS[0]
    d = m.Direction(
        unit="u1",
        status=m.DirectionStatus.EN_ROUTE,
        vector=(0.6, 0.8),
        heading_deg=math.degrees(math.atan2(0.6, 0.8)),
        lookahead=[(10.6, 20.8), (11.2, 21.6)],
    )
    assert geodetic.with_geodetic(d, None, (10.0, 20.0)) is d
    g = geodetic.with_geodetic(d, o, (10.0, 20.0))
    assert (
        g.true_bearing_deg is not None and abs(g.true_bearing_deg - d.heading_deg) < 0.01
    )  # near the origin
    assert len(g.lookahead_geo) == 2
    for p, q in zip(g.lookahead_geo, d.lookahead):
        assert np.allclose(o.to_local(p.lat, p.lon), q, atol=0.02)  # 1e-7 degrees is about a centimetre
    back = m.decode_direction(m.encode(g))
    assert back == g and isinstance(back.lookahead_geo[0], LatLon)
    still = m.Direction(unit="u1", status=m.DirectionStatus.ARRIVED, vector=(0.0, 0.0))
    assert geodetic.with_geodetic(still, o, (0.0, 0.0)).true_bearing_deg is None


# -- scenario files ---------------------------------------------------------------
METRES = {
    "start": (0.0, 0.0),
    "goal": (1800.0, 1400.0),
    "ridge": (700.0, 800.0),
    "farm": (1200.0, 500.0),
    "wood": (1000.0, 1150.0),
}
SHAPES = {
    "ridge": "facing_deg: 225, sigma_range: 120, sigma_lateral: 80, skew: 2",
    "farm": "facing_deg: 270, sigma_range: 100, sigma_lateral: 100",
    "wood": "facing_deg: 200, sigma_range: 90, sigma_lateral: 60, skew: 1",
}


def _scenario(pos) -> bytes:
    threats = "".join(f"  - {{id: {k}, position: {pos(k)}, {v}}}\n" for k, v in SHAPES.items())
    head = "origin: {lat: 58.4105, lon: 15.6213}\n"
    return f"{head}start: {pos('start')}\ngoal: {pos('goal')}\nthreats:\n{threats}".encode()


@pytest.mark.unit
def test_a_lat_lon_scenario_plans_the_metres_path_to_within_centimetres():
    """The lat/lon are Karney's (geographiclib), not ours: the check is independent of pymap3d."""
    from pfp_service.core import plan
    from pfp_service.scenario import decode_scenario

    o = Origin(lat=58.4105, lon=15.6213)

    def geodetic(k):
        lat, lon = _walk(o, *METRES[k])
        return f"{{lat: {lat!r}, lon: {lon!r}}}"

    in_metres = decode_scenario(_scenario(lambda k: list(METRES[k])), "yaml")
    in_degrees = decode_scenario(_scenario(geodetic), "yaml")
    assert in_degrees.origin == o
    runs = [plan(s.start, s.goal, s.schedule(), s.planner.to_params()) for s in (in_metres, in_degrees)]
    assert runs[0].status.value == runs[1].status.value == "reached"
    assert len(runs[0].path) == len(runs[1].path)
    gap = np.max(np.abs(np.asarray(runs[0].path) - np.asarray(runs[1].path)))
    assert gap < 0.01, gap


@pytest.mark.unit
def test_the_shipped_lat_lon_example_matches_its_metres():
    from pfp_service.scenario import load_scenario
    from tests.conftest import EXAMPLES

    s = load_scenario(EXAMPLES / "geo-simple.yaml")
    assert s.origin is not None and s.origin.alt == 90.0
    got = {"start": s.start, "goal": s.goal, **{t.id: t.position for t in s.threats}}
    for k, xy in METRES.items():  # the plane at 90 m is 14 ppm larger than the ellipsoid: 3 cm at 2.3 km
        assert np.allclose(got[k], xy, atol=0.05), (k, got[k])


@pytest.mark.unit
@pytest.mark.parametrize(
    ("doc", "path", "fragment"),
    [
        (b"start: {lat: 58.4, lon: 15.6}\ngoal: [1, 1]\n", "start", "needs a mission origin"),
        (b"origin: {lat: 95, lon: 0}\nstart: [0, 0]\ngoal: [1, 1]\n", "origin.lat", "must be < 89.9"),
        (b"origin: {lat: 58, lon: 15, x: 1}\nstart: [0, 0]\ngoal: [1, 1]\n", "origin.x", "unknown field"),
        (b"origin: 58.4\nstart: [0, 0]\ngoal: [1, 1]\n", "origin", "expected object"),
        (
            b"origin: {lat: 58, lon: 15}\nstart: [0, 0]\ngoal: [1, 1]\nthreats:\n"
            b"  - {position: {lat: 58, lon: 200}, sigma_range: 1, sigma_lateral: 1}\n",
            "threats[0].position.lon",
            "must be <= 180",
        ),
    ],
)
def test_bad_geodetic_scenarios_name_their_field(doc, path, fragment):
    from pfp_service.scenario import decode_scenario

    with pytest.raises(InputError) as e:
        decode_scenario(doc, "yaml")
    assert e.value.path == path and fragment in e.value.reason, str(e.value)


@pytest.mark.unit
def test_a_json_scenario_takes_lat_lon_too():
    from pfp_service.scenario import decode_scenario

    doc = {"origin": {"lat": 1.0, "lon": 2.0}, "start": {"lat": 1.0, "lon": 2.0}, "goal": [10, 0]}
    s = decode_scenario(json.dumps(doc).encode(), "json")
    assert np.allclose(s.start, (0.0, 0.0), atol=1e-9) and s.goal == (10.0, 0.0)


@pytest.mark.unit
def test_team_and_inject_files_take_lat_lon(tmp_path):
    from pfp_clients.script import load_script

    from pfp_service.team import load_team

    o = Origin(lat=48.0, lon=11.0)
    lat, lon = o.to_geodetic(30.0, 40.0)
    here = f"{{lat: {lat!r}, lon: {lon!r}}}"
    team = tmp_path / "team.yaml"
    team.write_text(f"origin: {{lat: 48.0, lon: 11.0}}\nunits:\n  - {{id: a, start: {here}, goal: [5, 5]}}\n")
    t = load_team(team)
    assert t.origin == o and np.allclose(t.units[0].start, (30.0, 40.0), atol=1e-6)
    script = tmp_path / "inject.yaml"
    script.write_text(
        "origin: {lat: 48.0, lon: 11.0}\ntimeline:\n"
        f"  - {{do: add_threat, threat: e1, position: {here}, sigma_range: 5, sigma_lateral: 3,"
        f" when: {{unit: a, within_m: 3, of: {here}}}}}\n"
        f"  - {{do: set_goal, unit: a, position: {here}}}\n"
    )
    s = load_script(script)
    add, goal = s.timeline
    assert np.allclose(add.position, (30.0, 40.0), atol=1e-6) and np.allclose(
        goal.position, (30.0, 40.0), atol=1e-6
    )
    assert add.when is not None and np.allclose(add.when.of, (30.0, 40.0), atol=1e-6)
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"units:\n  - {{id: a, start: {here}}}\n")
    with pytest.raises(InputError) as e:
        load_team(bad)
    assert e.value.path == "bad.yaml line 2, units[0].start" and "origin" in e.value.reason


@pytest.mark.unit
def test_serve_config_takes_an_origin_from_file_env_and_flag(tmp_path):
    from pfp_service.node.config import load_config

    toml = tmp_path / "serve.toml"
    toml.write_text("origin = { lat = 58.41, lon = 15.62, alt = 90 }\n")
    assert load_config(str(toml), {}, {}).origin == Origin(lat=58.41, lon=15.62, alt=90.0)
    assert load_config(None, {"PFP_ORIGIN": "59.5,18.25"}, {}).origin == Origin(lat=59.5, lon=18.25)
    flag = {"origin": {"lat": 1.0, "lon": 2.0}}
    assert load_config(str(toml), {"PFP_ORIGIN": "59.5,18.25"}, flag).origin == Origin(lat=1.0, lon=2.0)
    assert load_config(None, {}, {}).origin is None
    with pytest.raises(InputError) as e:
        load_config(None, {"PFP_ORIGIN": "north"}, {})
    assert e.value.path == "PFP_ORIGIN"


@pytest.mark.proc
def test_serve_origin_flag_is_one_line_exit_2():
    from tests.conftest import run_pfp

    out = run_pfp("serve", "--origin", "95,0", timeout=60)
    assert out.returncode == 2 and "Traceback" not in out.stderr and "--origin" in out.stderr


@pytest.mark.unit
def test_with_geodetic_without_a_position_uses_the_first_lookahead_point():
    o = ORIGINS[0]
    d = m.Direction(
        unit="u", status=m.DirectionStatus.EN_ROUTE, vector=(0.0, 1.0), lookahead=[(15_000.0, 1.0)]
    )
    at_unit = geo.true_bearing_deg(o, (15_000.0, 0.0), (0.0, 1.0))
    assert abs(geodetic.with_geodetic(d, o).true_bearing_deg - at_unit) < 1e-4
    bare = m.Direction(unit="u", status=m.DirectionStatus.EN_ROUTE, vector=(0.0, 1.0))
    assert geodetic.with_geodetic(bare, o).true_bearing_deg is None  # no position: not guessed


@pytest.mark.unit
def test_a_live_unit_reporting_lat_lon_gets_the_directions_of_one_reporting_metres():
    """Through the wire decoders and the world (the node passes ``cfg.origin`` to the decoders)."""
    from pfp_service.world.world import GoalSet, StateReported, ThreatPut, World, WorldSettings

    o = ORIGINS[0]

    def ll(x, y):
        lat, lon = o.to_geodetic(x, y)
        return {"lat": lat, "lon": lon}

    def run(pos):
        w = World(WorldSettings())
        threat = m.decode_threat(
            json.dumps(
                {"position": pos(60.0, 55.0), "sigma_range": 8, "sigma_lateral": 5, "facing_deg": 225}
            ).encode(),
            origin=o,
        )
        goal = m.decode_goal(json.dumps({"position": pos(120.0, 100.0)}).encode(), origin=o)
        w.apply([ThreatPut("t1", threat), GoalSet("u", goal)], 0.0)
        out = []
        for k, (x, y) in enumerate([(0.0, 0.0), (10.0, 8.0), (40.0, 30.0)]):
            state = m.decode_unit_state(json.dumps({"position": pos(x, y), "seq": k}).encode(), origin=o)
            out += [d for d in w.apply([StateReported("u", state)], 1.0 + k).directions if d.unit == "u"]
        return out

    metres, degrees = run(lambda x, y: [x, y]), run(ll)
    assert len(metres) == len(degrees) == 3
    for a, b in zip(metres, degrees):
        assert a.status == b.status and a.seq == b.seq
        assert (
            np.allclose(a.vector, b.vector, atol=1e-9) and abs(a.distance_to_goal - b.distance_to_goal) < 1e-6
        )
        assert np.allclose(a.lookahead, b.lookahead, atol=1e-6)


@pytest.mark.unit
def test_serve_config_bounds_may_be_lat_lon_corners(tmp_path):
    from pfp_service.node.config import load_config

    o = Origin(lat=58.41, lon=15.62)
    (a, b), (c, d) = o.to_geodetic(-500.0, -400.0), o.to_geodetic(800.0, 900.0)
    toml = tmp_path / "serve.toml"
    toml.write_text(
        "origin = { lat = 58.41, lon = 15.62 }\n"
        f"bounds = [{{ lat = {a!r}, lon = {b!r} }}, {{ lat = {c!r}, lon = {d!r} }}]\n"
    )
    (x0, y0), (x1, y1) = load_config(str(toml), {}, {}).bounds_tuple()
    assert np.allclose([x0, y0, x1, y1], [-500.0, -400.0, 800.0, 900.0], atol=1e-6)
    toml.write_text(f"bounds = [{{ lat = {a!r}, lon = {b!r} }}, [800, 900]]\n")
    with pytest.raises(InputError) as e:
        load_config(str(toml), {}, {})
    assert e.value.path.endswith("bounds[0]") and "origin" in e.value.reason


@pytest.mark.unit
def test_a_tick_of_directions_gets_the_lat_lon_each_would_get_alone():
    """``with_geodetic_many`` (one conversion for a tick) against the one-point conversions."""
    from pfp_service.wire import Direction, DirectionStatus

    origin = geo.Origin(lat=59.3, lon=18.0, alt=40.0)
    rng = np.random.default_rng(5)
    directions, positions = [], []
    for k in range(60):
        pts = [tuple(p) for p in rng.uniform(-20_000, 20_000, (k % 6, 2)).tolist()]
        vec = (0.0, 0.0) if k % 7 == 0 else (float(rng.normal()), float(rng.normal()))
        directions.append(
            Direction(unit=f"u{k}", seq=k, status=DirectionStatus.EN_ROUTE, vector=vec, lookahead=pts)
        )
        positions.append(None if k % 5 == 0 else tuple(rng.uniform(-20_000, 20_000, 2).tolist()))
    got = geodetic.with_geodetic_many(directions, origin, positions)
    for d, at, g in zip(directions, positions, got, strict=True):
        assert g.lookahead_geo == geo.lookahead_geodetic(origin, d.lookahead)
        here = at if at is not None else (d.lookahead[0] if d.lookahead else None)
        if here is None or d.vector == (0.0, 0.0):
            assert g.true_bearing_deg is None
        else:
            assert g.true_bearing_deg == pytest.approx(geo.true_bearing_deg(origin, here, d.vector), abs=1e-9)
    assert geodetic.with_geodetic_many(directions, None, positions) == directions
