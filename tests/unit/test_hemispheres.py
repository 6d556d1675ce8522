"""Origins south of the equator and west of Greenwich, written as the README writes them.

``pfp serve --origin -33.9,151.2`` once failed in argparse ("expected one
argument"): a value starting with a minus sign was taken for a flag.  Here a
real planner starts with such an origin, and a unit reporting ``{lat, lon}``
south-west of it gets the same direction as a unit reporting the same place in
metres, and both the direction the geometry gives.
"""

from __future__ import annotations

import math

import pytest

from pfp_service.cli import build_parser
from pfp_service.geo import parse_origin
from tests.zenoh_util import Inbox, client, planner_process, put_json

M = "hemi"
START = (-40.0, -30.0)  # south-west of the origin
GOAL = (60.0, 50.0)


def _latlon(origin, xy):
    lat, lon = origin.to_geodetic(*xy)
    return {"lat": lat, "lon": lon}


@pytest.mark.proc
@pytest.mark.parametrize("origin_text", ["-33.9,151.2", "-22.9,-43.2", "51.5,-0.12"])
def test_a_unit_in_lat_lon_gets_the_direction_of_the_same_place_in_metres(origin_text):
    origin = parse_origin(origin_text)
    planner = planner_process("--origin", origin_text, "--state-dir", "none", mission=M)
    with planner as (endpoint, _proc), client(endpoint) as s:
        directions = Inbox(s, f"mumt/{M}/unit/*/direction")
        units = {
            "geo": (_latlon(origin, START), _latlon(origin, GOAL)),
            "metres": (list(START), list(GOAL)),
        }
        start_geo = units["geo"][0]
        assert start_geo["lat"] < origin.lat and start_geo["lon"] < origin.lon  # south-west indeed
        got = {}
        for seq in range(1, 200):
            for uid, (position, goal) in units.items():
                if uid not in got:
                    put_json(s, f"mumt/{M}/unit/{uid}/goal", {"position": goal})
                    put_json(s, f"mumt/{M}/unit/{uid}/state", {"position": position, "seq": seq})
            try:
                while True:
                    d = directions.get(timeout=0.3, where=lambda d: d["status"] == "en_route")
                    got[d["unit"]] = d
            except TimeoutError:
                pass
            if len(got) == len(units):
                break
        assert set(got) == set(units), f"no direction for {set(units) - set(got)}"
    want = (GOAL[0] - START[0], GOAL[1] - START[1])
    norm = math.hypot(*want)
    for uid, d in got.items():
        assert d["vector"] == pytest.approx([want[0] / norm, want[1] / norm], abs=1e-4), uid
        assert d["distance_to_goal"] == pytest.approx(norm, abs=1e-3), uid
        assert d["true_bearing_deg"] is not None, uid  # the mission has an origin
    assert got["geo"]["true_bearing_deg"] == pytest.approx(got["metres"]["true_bearing_deg"], abs=1e-3)


@pytest.mark.unit
@pytest.mark.parametrize(
    ("argv", "dest", "value"),
    [
        (["serve", "--origin", "-33.9,151.2"], "origin", {"lat": -33.9, "lon": 151.2, "alt": 0.0}),
        (["serve", "--origin", "-33.9,-70.6,-5"], "origin", {"lat": -33.9, "lon": -70.6, "alt": -5.0}),
        (["serve", "--bounds", "[[-10,-10],[10,10]]"], "bounds", [[-10, -10], [10, 10]]),
        (
            ["handheld", "--unit", "u", "--goal", "-10,-5.5"],
            "goal",
            "-10,-5.5",
        ),  # read once the origin is known
        (["handheld", "--unit", "u", "--start", "-.5,3"], "start", (-0.5, 3.0)),
        (["map", "--origin", "-0.5,-78.5"], "origin", None),
        (["tak", "--origin", "-33.9,151.2"], "origin", None),
        (["tak", "--origin", "0,0", "--facing-deg", "-30"], "facing_deg", -30.0),
    ],
)
def test_every_coordinate_flag_takes_a_negative_value_as_written(argv, dest, value):
    args = build_parser().parse_args(argv)
    got = getattr(args, dest)
    if value is None:  # an Origin
        want = parse_origin(argv[argv.index("--origin") + 1])
        assert got == want
    else:
        assert got == value


@pytest.mark.unit
def test_a_word_that_is_a_flag_is_still_a_flag():
    with pytest.raises(SystemExit):
        build_parser().parse_args(["serve", "--origin", "--mission", "m"])  # --origin lacks its value
