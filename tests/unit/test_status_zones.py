"""``pfp status``'s keep-out zones table: shape in words, centroid in the chosen coordinates, TTL left."""

from __future__ import annotations

import re

import pytest

from pfp_service.cli.status import planner_lines, snapshot_lines, zone_centroid, zone_shape
from pfp_service.coords import Coords
from pfp_service.wire import Origin, PlannerStatus, WorldSnapshot
from pfp_service.wire.messages import ZoneCircle, ZoneSummary, ZoneUpdate

pytestmark = pytest.mark.unit

ORIGIN = Origin(lat=58.4105, lon=15.6213)
SQUARE = [[(100.0, 0.0), (120.0, 0.0), (120.0, 20.0), (100.0, 20.0), (100.0, 0.0)]]
HOLES = [
    [(0.0, 0.0), (40.0, 0.0), (40.0, 10.0), (0.0, 10.0), (0.0, 0.0)],
    [(2.0, 2.0), (4.0, 2.0), (4.0, 4.0), (2.0, 2.0)],
    [(30.0, 2.0), (34.0, 2.0), (34.0, 6.0), (30.0, 2.0)],
]


def _snap(zones: list[ZoneSummary], total: int | None = None) -> WorldSnapshot:
    return WorldSnapshot(
        planner="p1", mission="m", zones=zones, zones_total=len(zones) if total is None else total
    )


def test_shapes_are_said_in_words_and_placed_at_their_centroid():
    circle = ZoneUpdate(circle=ZoneCircle(centre=(-40.0, 75.0), radius_m=25.0))
    assert zone_shape(circle) == "circle, radius 25.0 m" and zone_centroid(circle) == (-40.0, 75.0)
    square = ZoneUpdate(polygon=SQUARE)
    assert zone_shape(square) == "polygon, 4 vertices" and zone_centroid(square) == pytest.approx(
        (110.0, 10.0)
    )
    holed = ZoneUpdate(polygon=HOLES)
    assert zone_shape(holed) == "polygon, 4 vertices, 2 holes"
    # the holes (area 2 near x=3.3, area 8 near x=32.7) pull the centroid off (20, 5)
    x = (400 * 20 - 2 * (10 / 3) - 8 * (98 / 3)) / 390
    assert zone_centroid(holed)[0] == pytest.approx(x)


def test_the_table_lists_each_zone_in_natural_order_with_its_ttl():
    zones = [
        ZoneSummary(id="z10", zone=ZoneUpdate(polygon=SQUARE), ttl_s=12.34),
        ZoneSummary(id="z2", zone=ZoneUpdate(circle=ZoneCircle(centre=(5.0, 6.0), radius_m=3.0))),
    ]
    lines = snapshot_lines(_snap(zones))
    assert lines[0] == "planner p1, mission m: 0 units, 0 threats, 2 zones"
    text = "\n".join(lines)
    assert re.search(r"^zone\s+kind\s+shape\s+centroid\s+TTL left$", text, re.M)
    rows = [ln for ln in lines if ln.startswith("z") and not ln.startswith("zone ")]
    assert re.fullmatch(r"z2\s+keep_out\s+circle, radius 3\.0 m\s+\(5\.0, 6\.0\)\s+no expiry", rows[0])
    assert re.fullmatch(r"z10\s+keep_out\s+polygon, 4 vertices\s+\(110\.0, 10\.0\)\s+12\.3 s", rows[1])
    assert "more zones" not in text
    more = snapshot_lines(_snap(zones, total=5))
    assert more[-1] == "... and 3 more zones (--json lists them all)"
    assert snapshot_lines(_snap([]))[1:] == []  # no zones: no table


@pytest.mark.parametrize("style", ["latlon", "mgrs"])
def test_the_centroid_is_shown_in_the_chosen_coordinates(style):
    coords = Coords.choose(style, ORIGIN)
    zones = [ZoneSummary(id="sq", zone=ZoneUpdate(polygon=SQUARE))]
    (row,) = [ln for ln in snapshot_lines(_snap(zones), coords) if ln.startswith("sq")]
    assert coords.point((110.0, 10.0)) in row  # the same words as a threat or unit at that point


def test_the_planner_table_counts_zones():
    st = PlannerStatus(planner="p1", mission="m", uptime_s=1.0, threats=3, zones=7)
    header, row = planner_lines([st])
    assert header.split()[4:6] == ["threats", "zones"] and row.split()[4:6] == ["3", "7"]
