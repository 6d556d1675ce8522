"""Keep-out zones in the engine: no path enters one, and what the planner says when it cannot plan."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pfp_service.core import PlannerParams, Scheduled, Threat, ThreatField, plan
from pfp_service.core.batch import advise_many
from pfp_service.core.optimal import plan_optimal
from pfp_service.core.params import resolve
from pfp_service.core.stepper import Stepper, StepStatus
from pfp_service.core.steprule import judge_zoned, unit
from pfp_service.core.zones import Zone, ZoneSet, track_enters
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.geojson import feature_collection, zones_from_geojson
from pfp_service.scenario import decode_scenario

WALL = ZoneSet([Zone.polygon("wall", [(40, -30), (45, -30), (45, 30), (40, 30)])])
RING = ZoneSet(
    [
        Zone.polygon(
            "ring",
            [(-20, -20), (20, -20), (20, 20), (-20, 20)],
            [[(-10, -10), (10, -10), (10, 10), (-10, 10)]],
        )
    ]
)


@pytest.mark.unit
@pytest.mark.parametrize("escape", ["auto", "global"])
def test_a_wall_across_the_line_is_gone_round_and_never_entered(escape: str) -> None:
    r = plan((0, 0), (100, 0), params=PlannerParams(escape=escape), zones=WALL)
    assert r.status.value == "reached", r.reason
    assert track_enters(WALL, r.path) is None
    assert r.min_zone_clearance is not None and r.min_zone_clearance > 0
    if escape == "auto":  # foreseen: round the nearer end from the start, near the shortest way
        assert r.length < 1.05 * (50 + 5 + math.hypot(55, 30))


@pytest.mark.unit
def test_plain_descent_never_steps_into_a_zone_and_ends_trapped_honestly() -> None:
    r = plan((0, 0), (100, 0), params=PlannerParams(escape="none"), zones=WALL)
    assert r.status.value == "trapped"
    assert track_enters(WALL, r.path) is None


@pytest.mark.unit
def test_the_barrier_bends_descent_past_an_oblique_zone() -> None:
    slab = ZoneSet([Zone.polygon("slab", [(40, -5), (44, -5), (64, 15), (60, 15)])])  # 45 degrees to the line
    r = plan((0, 0), (100, 0), params=PlannerParams(escape="none"), zones=slab)
    assert r.status.value == "reached", r.reason
    assert track_enters(slab, r.path) is None and not r.escapes


@pytest.mark.unit
def test_a_goal_in_a_zone_is_trapped_naming_it() -> None:
    r = plan((0, 0), (42, 0), zones=WALL)
    assert r.status.value == "trapped" and r.reason == "the goal lies in zone wall"
    o = plan_optimal((0, 0), (42, 0), zones=WALL)
    assert o.status.value == "trapped" and "zone wall" in o.reason


@pytest.mark.unit
def test_a_unit_in_a_zone_leaves_by_the_shortest_way_out_and_says_so() -> None:
    r = plan((41, 0), (100, 0), zones=WALL)
    assert r.status.value == "reached", r.reason
    assert r.escapes[0] == "leave zone wall"
    assert r.events[0] == "start inside zone wall: left it by the shortest way out"
    assert r.path[1][0] < 41  # out by the near edge (x = 40), not through the far one
    out = next(i for i, p in enumerate(r.path) if not WALL.zone_at(*p))
    assert out <= 4 and track_enters(WALL, r.path[out:]) is None  # out within 1.7 m, and never back in


@pytest.mark.unit
def test_a_unit_enclosed_by_a_zone_is_trapped_naming_it() -> None:
    r = plan((0, 0), (100, 0), zones=RING)
    assert r.status.value == "trapped"
    assert "zone ring" in r.reason, r.reason
    assert track_enters(RING, r.path) is None
    o = plan_optimal((0, 0), (100, 0), zones=RING, avoid_cores=True)
    assert o.status.value == "trapped"


@pytest.mark.unit
def test_zones_and_cores_together() -> None:
    threats = [Scheduled(Threat.from_facing((50, 8 * k), 0, 4, 4, 0, id=f"t{k}")) for k in range(-3, 4)]
    plug = ZoneSet([Zone.polygon("plug", [(47, 20), (53, 20), (53, 60), (47, 60)])])
    r = plan((0, 0), (100, 0), threats, zones=plug)
    assert r.status.value == "reached", r.reason
    assert track_enters(plug, r.path) is None
    assert np.mean(np.array(r.path)[:, 1]) < 0  # round the open end, below


@pytest.mark.unit
def test_a_thin_zone_is_never_crossed() -> None:
    thin = ZoneSet([Zone.polygon("wire", [(50, -20), (50.005, -20), (50.005, 20), (50, 20)])])
    for escape in ("none", "auto"):
        r = plan((0, 0), (100, 0), params=PlannerParams(escape=escape), zones=thin)
        assert track_enters(thin, r.path) is None
    o = plan_optimal((0, 0), (100, 0), zones=thin, avoid_cores=True)
    assert o.status.value == "reached" and track_enters(thin, o.path) is None


@pytest.mark.unit
@settings(max_examples=60, deadline=None)
@given(
    st.floats(5, 95), st.floats(-40, 40), st.floats(0, 2 * math.pi), st.floats(0.5, 8.0), st.floats(0.2, 3.0)
)
def test_judge_zoned_never_ends_a_step_in_a_zone(
    x: float, y: float, ang: float, r: float, step: float
) -> None:
    zs = ZoneSet([Zone.circle("c", (50.0, 0.0), r), *WALL.zones])
    if zs.zone_at(x, y):
        return
    u = unit((100.0, 0.0), 1e-4, 0.1, step, watch=False)
    fx, fy = -math.cos(ang), -math.sin(ang)
    *_, tx, ty = judge_zoned(u, *zs.packed(), x, y, fx, fy, 1.0)
    assert track_enters(zs, [(x, y), (tx, ty)]) is None
    assert math.hypot(tx - x, ty - y) <= step + 1e-9


@pytest.mark.unit
def test_advise_many_keeps_the_zone_rules() -> None:
    params = resolve(PlannerParams(), (0, 0), (100, 0), [])
    field = ThreatField([]).with_zones(WALL)
    steppers = [
        Stepper((0, 0), (100, 0), params),
        Stepper((0, 0), (42, 0), params),
        Stepper((41, 0), (100, 0), params),
    ]
    out = advise_many(steppers, field, np.array([[0.0, 0.0], [0.0, 0.0], [41.0, 0.0]]))
    assert out[0].status in (StepStatus.EN_ROUTE, StepStatus.ESCAPING)  # the look-ahead may go round at once
    assert out[1].status is StepStatus.TRAPPED and out[1].reason == "the goal lies in zone wall"
    assert out[2].status is StepStatus.ESCAPING and out[2].dx < 0


@pytest.mark.unit
def test_scenario_zones_in_metres_and_lat_lon() -> None:
    doc = {
        "origin": {"lat": 59.0, "lon": 18.0},
        "start": [0, 0],
        "goal": [100, 0],
        "zones": [
            {"id": "wall", "polygon": [[[40, -30], [45, -30], [45, 30], [40, 30], [40, -30]]]},
            {"circle": {"centre": {"lat": 59.0003, "lon": 18.0013}, "radius_m": 5}},
        ],
    }
    sc = decode_scenario(json.dumps(doc).encode(), "json")
    zs = sc.zone_set()
    assert zs.ids == ("wall", "z2")
    c = zs.get("z2")
    assert c is not None and c.centre is not None and c.centre[1] == pytest.approx(33.4, abs=0.5)


@pytest.mark.unit
@pytest.mark.parametrize(
    ("zones", "path", "reason"),
    [
        ([{"polygon": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]}], "zones[0].polygon[0]", "crosses itself"),
        (
            [{"circle": {"centre": [0, 0], "radius_m": 1}, "colour": "red"}],
            "zones[0].colour",
            "unknown field",
        ),
        ([{"id": "a", "circle": {"centre": [0, 0], "radius_m": 1}}] * 2, "zones[1].id", "duplicate"),
    ],
)
def test_bad_scenario_zones_name_the_field(zones: list[object], path: str, reason: str) -> None:
    doc = {"start": [0, 0], "goal": [100, 0], "zones": zones}
    with pytest.raises(InputError) as e:
        decode_scenario(json.dumps(doc).encode(), "json")
    assert e.value.path == path and reason in e.value.reason, str(e.value)


ORIGIN = Origin(lat=59.0, lon=18.0)


def _square(lon: float, lat: float, d: float) -> list[list[float]]:
    return [[lon, lat], [lon + d, lat], [lon + d, lat + d], [lon, lat + d], [lon, lat]]


@pytest.mark.unit
def test_geojson_polygons_and_multipolygons_become_zones_and_go_back_out() -> None:
    doc = {
        "type": "FeatureCollection",
        "features": [
            {"type": "Feature", "id": "mines", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [_square(18.001, 59.0, 0.001), _square(18.0013, 59.0003, 0.0003)]}},
            {"type": "Feature", "properties": {"name": "river"}, "geometry": {"type": "MultiPolygon", "coordinates": [[_square(18.01, 59.0, 0.001)], [_square(18.02, 59.0, 0.001)]]}},
            {"type": "Feature", "properties": {"name": "has space"}, "geometry": {"type": "Polygon", "coordinates": [_square(18.03, 59.0, 0.001)]}},
        ],
    }  # fmt: skip
    zones = zones_from_geojson(doc, ORIGIN, "z.geojson")
    assert [z.id for z in zones] == ["mines", "river-1", "river-2", "zone-4"]
    assert len(zones[0].holes) == 1 and zones[0].bounds()[0] == pytest.approx(57.4, abs=0.5)
    fc = feature_collection(ORIGIN, [], zones=zones)
    out = [f for f in fc["features"] if f["properties"]["kind"] == "keep_out"]
    assert [f["properties"]["id"] for f in out] == ["mines", "river-1", "river-2", "zone-4"]
    again = zones_from_geojson({"type": "FeatureCollection", "features": out}, ORIGIN)
    assert again[0].geometry.symmetric_difference(zones[0].geometry).area < 1.0  # m², rounding to 1e-7 deg


@pytest.mark.unit
@pytest.mark.parametrize(
    ("doc", "where", "reason"),
    [
        ({"type": "Point", "coordinates": [18, 59]}, "z.geojson: type", "expected FeatureCollection"),
        ({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": [[18, 59], [18.1, 59]]}}]}, "z.geojson: features[0].geometry", "Polygon or MultiPolygon"),
        ({"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [[[18, 59], [18.001, 59.001], [18.001, 59], [18, 59.001], [18, 59]]]}}, "z.geojson: geometry", "Self-intersection"),
        ({"type": "Polygon", "coordinates": [[[18, 59], [18.001, 59]]]}, "z.geojson: geometry", "not a valid Polygon"),
    ],
)  # fmt: skip
def test_bad_geojson_names_the_file_and_feature(doc: dict[str, object], where: str, reason: str) -> None:
    with pytest.raises(InputError) as e:
        zones_from_geojson(doc, ORIGIN, "z.geojson")
    assert e.value.path == where and reason in e.value.reason, str(e.value)


@pytest.mark.proc
def test_pfp_plan_zones_flag(tmp_path: Path) -> None:
    import subprocess
    import sys

    sc = tmp_path / "s.yaml"
    sc.write_text("origin: {lat: 59.0, lon: 18.0}\nstart: [0, 0]\ngoal: [100, 0]\n")
    zf = tmp_path / "z.geojson"
    wall = [
        [18.0007, 58.9997],
        [18.0008, 58.9997],
        [18.0008, 59.0003],
        [18.0007, 59.0003],
        [18.0007, 58.9997],
    ]
    zf.write_text(json.dumps({"type": "Polygon", "coordinates": [wall]}))
    run = [sys.executable, "-m", "pfp_service", "plan", str(sc), "--json", "--zones", str(zf)]
    r = subprocess.run(run, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["status"] == "reached" and out["min_zone_clearance"] > 0
    zs = zones_from_geojson(json.loads(zf.read_text()), ORIGIN)
    assert track_enters(zs, out["path"]) is None
    bad = tmp_path / "bad.geojson"
    bad.write_text(
        json.dumps(
            {
                "type": "Polygon",
                "coordinates": [[[18, 59], [18.001, 59.001], [18.001, 59], [18, 59.001], [18, 59]]],
            }
        )
    )
    r = subprocess.run([*run[:-1], str(bad)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert (
        len(r.stderr.strip().splitlines()) == 1 and str(bad) in r.stderr and "Self-intersection" in r.stderr
    )
