"""``pfp serve --origin`` on loopback Zenoh: lat/lon units get the metres directions, previews answer GeoJSON."""

from __future__ import annotations

import json

import numpy as np
import pytest
from geojson_pydantic import FeatureCollection

from pfp_service.geo import Origin
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from tests.zenoh_util import Inbox, client, planner_process, put_in_force, put_json

ORIGIN = Origin(lat=58.4105, lon=15.6213)
MISSION = "geo"


def _ll(x: float, y: float) -> dict[str, float]:
    lat, lon = ORIGIN.to_geodetic(x, y)
    return {"lat": lat, "lon": lon}


@pytest.fixture(scope="module")
def planner():
    with planner_process("--origin", f"{ORIGIN.lat},{ORIGIN.lon}", mission=MISSION) as (endpoint, _p):
        yield endpoint


@pytest.mark.proc
def test_a_unit_reporting_lat_lon_gets_the_directions_of_one_reporting_metres(planner):
    with client(planner) as s:
        inboxes = {u: Inbox(s, keys.unit_direction(MISSION, u)) for u in ("metres", "degrees")}
        ridge = {
            "position": _ll(300.0, 260.0),
            "facing_deg": 225,
            "sigma_range": 60,
            "sigma_lateral": 40,
            "skew": 1,
        }
        put_in_force(
            s,
            MISSION,
            {
                keys.threat(MISSION, "ridge"): ridge,
                keys.unit_goal(MISSION, "metres"): {"position": [600.0, 500.0]},
                keys.unit_goal(MISSION, "degrees"): {"position": _ll(600.0, 500.0)},
            },
        )
        for seq, (x, y) in enumerate([(0.0, 0.0), (50.0, 40.0), (120.0, 90.0)], start=1):
            put_json(s, keys.unit_state(MISSION, "metres"), {"position": [x, y], "seq": seq})
            put_json(s, keys.unit_state(MISSION, "degrees"), {"position": _ll(x, y), "seq": seq})
            a = inboxes["metres"].get(timeout=10, where=lambda d, k=seq: d.get("seq") == k)
            b = inboxes["degrees"].get(timeout=10, where=lambda d, k=seq: d.get("seq") == k)
            assert a["status"] == b["status"] == "en_route"
            assert np.allclose(a["vector"], b["vector"], atol=1e-9)
            assert abs(a["distance_to_goal"] - b["distance_to_goal"]) < 1e-6
            assert np.allclose(a["lookahead"], b["lookahead"], atol=1e-6)
            assert a["true_bearing_deg"] == pytest.approx(b["true_bearing_deg"], abs=1e-6)
            assert len(b["lookahead_geo"]) == len(b["lookahead"]) > 0
            first = b["lookahead_geo"][0]
            assert ORIGIN.to_local(first["lat"], first["lon"]) == pytest.approx(b["lookahead"][0], abs=0.02)
        (reply,) = [
            r for r in s.get(keys.preview(MISSION, "degrees"), payload=b'{"geojson": true}', timeout=10.0)
        ]
        assert reply.ok is not None, reply.err.payload.to_bytes() if reply.err is not None else None
        fc = json.loads(reply.ok.payload.to_bytes())
        FeatureCollection.model_validate(fc)
        kinds = [f["properties"]["kind"] for f in fc["features"]]
        assert kinds.count("path") == 1 and "zone" in kinds and "core" in kinds
        for u in ("metres", "degrees"):
            s.delete(keys.unit_goal(MISSION, u))
        s.delete(keys.threat(MISSION, "ridge"))


@pytest.mark.proc
def test_without_an_origin_lat_lon_is_rejected_with_its_path():
    with planner_process(mission="geo0") as (endpoint, _p), client(endpoint) as s:
        rejected = Inbox(s, keys.event("geo0", "rejected"))
        put_json(s, keys.unit_state("geo0", "u"), {"position": {"lat": 58.4, "lon": 15.6}})
        ev = rejected.get(timeout=10)
        assert ev["field"] == "$.position" and "origin" in ev["reason"]
        directions = Inbox(s, keys.unit_direction("geo0", "u"))
        put_json(s, keys.unit_goal("geo0", "u"), {"position": [10.0, 10.0]})
        put_json(s, keys.unit_state("geo0", "u"), {"position": [0.0, 0.0], "seq": 1})
        directions.get(timeout=10, where=lambda d: d.get("seq") == 1)
        (reply,) = list(s.get(keys.preview("geo0", "u"), payload=b'{"geojson": true}', timeout=5.0))
        assert reply.err is not None
        err = m.decode_error_reply(reply.err.payload.to_bytes())
        assert err.field == "$.geojson" and "origin" in err.error
