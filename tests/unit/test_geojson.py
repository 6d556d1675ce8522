"""GeoJSON export: RFC 7946 structure (checked by geojson-pydantic), [lon, lat] order, precision, rings."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from geojson_pydantic import FeatureCollection
from pydantic import ValidationError

from pfp_service import geojson
from pfp_service.core import Threat, ThreatField, plan
from pfp_service.core.cores import Cores
from pfp_service.geo import Origin
from pfp_service.scenario import load_scenario
from tests.conftest import EXAMPLES, run_pfp

ORIGIN = Origin(lat=58.4105, lon=15.6213)


def _signed_area(ring: list[list[float]]) -> float:
    return 0.5 * sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(ring, ring[1:]))


def _decimals(v: float) -> int:
    text = repr(v)
    return len(text.split(".")[1]) if "." in text and "e" not in text else 0


def _check(fc: dict) -> None:
    """What the validator does not: precision, order, closure and winding."""
    FeatureCollection.model_validate(fc)
    assert "crs" not in fc
    for f in fc["features"]:
        g = f["geometry"]
        coords = g["coordinates"]
        flat = [coords] if g["type"] == "Point" else coords if g["type"] == "LineString" else coords[0]
        for lon, lat in flat:
            assert -180 <= lon <= 180 and -90 <= lat <= 90
            assert _decimals(lon) <= 7 and _decimals(lat) <= 7
        if g["type"] == "Polygon":
            (ring,) = coords
            assert ring[0] == ring[-1] and len(ring) >= 4
            assert _signed_area(ring) > 0, "exterior rings run counter-clockwise (RFC 7946 3.1.6)"


@pytest.mark.unit
def test_a_scenario_exports_a_valid_feature_collection():
    s = load_scenario(EXAMPLES / "geo-simple.yaml")
    r = plan(s.start, s.goal, s.schedule(), s.planner.to_params())
    fc = geojson.scenario_collection(s, r)
    _check(fc)
    kinds = [f["properties"]["kind"] for f in fc["features"]]
    assert kinds.count("path") == 1 and kinds.count("threat") == 3
    assert kinds.count("zone") == 3 and kinds.count("core") == 3
    path = next(f for f in fc["features"] if f["properties"]["kind"] == "path")
    assert path["properties"]["status"] == "reached"
    assert path["properties"]["length"] == pytest.approx(r.length)
    assert {"exposure", "peak_threat", "min_clearance", "final_distance", "steps"} <= path[
        "properties"
    ].keys()
    # [lon, lat], not [lat, lon]: the start is the origin
    assert path["geometry"]["coordinates"][0] == [15.6213, 58.4105]
    ridge = next(
        f
        for f in fc["features"]
        if f["properties"].get("id") == "ridge" and f["properties"]["kind"] == "threat"
    )
    assert ridge["properties"]["sigma_range"] == 120 and ridge["properties"]["facing_deg"] == 225
    json.dumps(fc, allow_nan=False)  # no NaN or infinity anywhere


@pytest.mark.unit
def test_the_validator_is_not_a_rubber_stamp():
    open_ring = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1]]]},
            }
        ],
    }
    with pytest.raises(ValidationError):
        FeatureCollection.model_validate(open_ring)


@pytest.mark.unit
@pytest.mark.parametrize(("facing", "sr", "sl"), [(0.0, 100.0, 50.0), (135.0, 30.0, 80.0)])
def test_unskewed_zones_are_the_analytic_ellipses(facing, sr, sl):
    """Without skew the level-L set is the ellipse of Mahalanobis radius sqrt(2 ln(1/L))."""
    t = Threat.from_facing((200.0, -100.0), facing, sr, sl, 0.0, 1.0, "e")
    for level in (0.1, 0.5):
        ring = geojson.zone_ring(t, level)
        p00, p01, p11 = t.precision()
        dx, dy = ring[:, 0] - 200.0, ring[:, 1] + 100.0
        m2 = p00 * dx * dx + 2 * p01 * dx * dy + p11 * dy * dy
        assert np.allclose(np.sqrt(m2), math.sqrt(2 * math.log(1 / level)), rtol=1e-9)


@pytest.mark.unit
def test_skewed_zone_boundaries_sit_at_their_level_and_hold_the_core():
    t = Threat.from_facing((0.0, 0.0), 60.0, 40.0, 25.0, 3.0, 2.0, "s")
    cores = Cores(ThreatField([t]))
    zone, core = geojson.zone_ring(t, 0.1), geojson.zone_ring(t, 0.5)
    assert np.allclose(cores.ratio(zone)[0], 0.1, atol=1e-9)
    assert np.allclose(cores.ratio(core)[0], 0.5, atol=1e-9)
    assert cores.inside(core * 0.999 + 0.001 * np.array(t.mode())).all()
    area = lambda r: 0.5 * abs(np.sum(r[:, 0] * np.roll(r[:, 1], -1) - np.roll(r[:, 0], -1) * r[:, 1]))
    assert area(core) < area(zone)
    # the mode lies forward of the enemy position: skew pushes the zone along the facing (60 deg)
    mx, my = t.mode()
    assert mx > 0 and my > 0 and math.isclose(math.degrees(math.atan2(mx, my)), 60.0, abs_tol=1e-6)


@pytest.mark.unit
def test_threats_only_and_weightless_threats():
    ts = [Threat.from_facing((0.0, 0.0), 0.0, 10.0, 10.0, 0.0, 0.0, "ghost")]
    fc = geojson.feature_collection(ORIGIN, ts, level=0.2)
    _check(fc)
    assert [f["properties"]["kind"] for f in fc["features"]] == ["threat"]  # weight 0: no zone, no core
    with pytest.raises(ValueError, match="level"):
        geojson.feature_collection(ORIGIN, ts, level=1.0)


@pytest.mark.proc
def test_plan_cli_writes_geojson(tmp_path):
    out = tmp_path / "plan.geojson"
    r = run_pfp("plan", str(EXAMPLES / "geo-simple.yaml"), "--geojson", str(out), "--zone-level", "0.2")
    assert r.returncode == 0, r.stderr
    fc = json.loads(out.read_text())
    _check(fc)
    zones = [f for f in fc["features"] if f["properties"]["kind"] == "zone"]
    assert zones and all(f["properties"]["level"] == 0.2 for f in zones)


@pytest.mark.proc
@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        ([str(EXAMPLES / "paper-simple.yaml"), "--geojson", "{tmp}/x.geojson"], "has no origin"),
        ([str(EXAMPLES / "geo-simple.yaml"), "--geojson", "{tmp}/x.txt"], "must end in .geojson"),
        ([str(EXAMPLES / "geo-simple.yaml"), "--geojson", "{tmp}/no/x.geojson"], "does not exist"),
        (
            [str(EXAMPLES / "geo-simple.yaml"), "--geojson", "{tmp}/x.geojson", "--zone-level", "1"],
            "between 0 and 1",
        ),
    ],
)
def test_plan_cli_geojson_edges_are_one_line_exit_2(tmp_path, args, fragment):
    r = run_pfp("plan", *[a.replace("{tmp}", str(tmp_path)) for a in args])
    assert r.returncode == 2 and "Traceback" not in r.stderr and fragment in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) <= 3  # argparse adds its usage line for a bad flag value


@pytest.mark.unit
def test_preview_request_geojson_option_is_not_a_what_if():
    from pfp_service.wire import messages as m

    assert m.decode_preview_request(b'{"geojson": true}').geojson is True
    assert not m.decode_preview_request(b'{"geojson": true}').what_if
    assert m.decode_preview_request(b'{"geojson": true, "goal": [1, 2]}').what_if


@pytest.mark.unit
def test_preview_reply_body_and_its_refusal_without_an_origin():
    from pfp_service.errors import InputError

    t = Threat.from_facing((50.0, 50.0), 0.0, 10.0, 10.0, 0.0, 1.0, "a")
    s = load_scenario(EXAMPLES / "geo-simple.yaml")
    r = plan(s.start, s.goal, s.schedule(), s.planner.to_params())
    body = geojson.preview_reply(ORIGIN, r, [t], start=s.start, goal=s.goal)
    _check(json.loads(body))
    with pytest.raises(InputError) as e:
        geojson.preview_reply(None, r, [t])
    assert e.value.path == "$.geojson" and "origin" in e.value.reason
