"""Team files' keep-out ``zones:``: read in metres or ``{lat, lon}`` (unit), and put by ``pfp fleet`` (proc)."""

from __future__ import annotations

import json
import uuid

import pytest
import shapely

from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.team import load_team, zone_updates
from pfp_service.wire import decode_world_snapshot, keys
from pfp_service.world import translate
from tests.conftest import run_pfp
from tests.zenoh_util import client, planner_process

TEAM = """\
name: zoned
units:
  - {id: a1, kind: unmanned, start: [0, 20], goal: [80, 20], speed_mps: 2.0}
zones:
  - {id: wall, polygon: [[[40, 5], [46, 5], [46, 35], [40, 35], [40, 5]]]}
  - {circle: {centre: [20, 60], radius_m: 6}, ttl_s: 600}
"""


@pytest.mark.unit
def test_a_team_files_zones_are_read_with_their_ids(tmp_path):
    p = tmp_path / "team.yaml"
    p.write_text(TEAM)
    team = load_team(p)
    got = dict(zone_updates(team))
    assert list(got) == ["wall", "z2"]  # an id left out is zN, as in scenario files
    assert got["z2"].circle is not None and got["z2"].ttl_s == 600
    assert translate.zone(got["wall"], "wall").contains(43.0, 20.0)


@pytest.mark.unit
def test_team_zones_take_lat_lon_from_the_teams_origin(tmp_path):
    o = Origin(lat=58.4105, lon=15.6213)
    p = tmp_path / "team.yaml"
    p.write_text(
        f"origin: {{lat: {o.lat}, lon: {o.lon}}}\n"
        "units:\n  - {id: a1, start: [0, 0]}\n"
        "zones:\n  - id: pond\n    circle: {centre: {lat: 58.4115, lon: 15.6213}, radius_m: 10}\n"
    )
    ((zid, z),) = zone_updates(load_team(p))
    assert zid == "pond" and z.circle is not None
    assert z.circle.centre == pytest.approx(o.to_local(58.4115, 15.6213), abs=1e-6)


@pytest.mark.unit
@pytest.mark.parametrize(
    ("zones", "where"),
    [
        (
            "  - {id: a, circle: {centre: [0, 0], radius_m: 1}}\n  - {id: a, circle: {centre: [5, 0], radius_m: 1}}\n",
            "zones[1].id",
        ),
        (
            "  - {polygon: [[[0, 0], [1, 0], [1, 1], [0, 0]]]}\n  - {polygon: [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]}\n",
            "zones[1]",
        ),
    ],
)
def test_a_bad_team_zone_is_refused_naming_the_file_and_the_zone(tmp_path, zones, where):
    p = tmp_path / "team.yaml"
    p.write_text("units:\n  - {id: a1, start: [0, 0]}\nzones:\n" + zones)
    with pytest.raises(InputError) as got:
        load_team(p)
    assert "team.yaml" in got.value.path and where in got.value.path + got.value.reason


@pytest.mark.proc
def test_pfp_fleet_puts_the_teams_zones_and_its_unit_goes_round_them(tmp_path):
    mission = "tz" + uuid.uuid4().hex[:8]
    p = tmp_path / "team.yaml"
    p.write_text(TEAM)
    track: list[tuple[float, float]] = []
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, _), client(endpoint) as s:
        sub = s.declare_subscriber(  # the unit's reports, on whichever key the fleet publishes them
            keys.unit_states_any(mission),
            lambda smp: track.append(tuple(json.loads(smp.payload.to_bytes())["position"])),
        )
        r = run_pfp(
            "fleet", "--team", str(p), "--connect", endpoint, "--mission", mission,
            "--speed-up", "20", "--until-arrived", "--duration-s", "120", timeout=90,
        )  # fmt: skip
        sub.undeclare()
        assert r.returncode == 0, r.stdout + r.stderr
        assert "keep-out zone wall put" in r.stdout and "all arrived" in r.stdout, r.stdout[-3000:]
        (reply,) = [x for x in s.get(keys.worlds(mission), timeout=5) if x.ok is not None]
        snap = decode_world_snapshot(reply.ok.payload.to_bytes())
        assert sorted(z.id for z in snap.zones) == ["wall", "z2"]
    assert len(track) > 10
    wall = shapely.Polygon([(40, 5), (46, 5), (46, 35), (40, 35)])
    assert not shapely.LineString(track).intersects(wall), "the unit's reported track enters the wall"
