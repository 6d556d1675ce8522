"""``pfp status`` and ``pfp health`` as a user runs them, against a real planner subprocess."""

from __future__ import annotations

import json
import re
import time
import uuid

import pytest

from tests.conftest import run_pfp
from tests.proc.test_serve import Unit
from tests.zenoh_util import client, planner_process, put_json


@pytest.fixture(scope="module")
def world():
    """A planner holding two units (one with a goal), two threats (one with a TTL) and two keep-out zones."""
    mission = "w" + uuid.uuid4().hex[:10]
    with planner_process(mission=mission) as (endpoint, _), client(endpoint) as s:
        put_json(
            s, f"mumt/{mission}/threat/e1", {"position": [4, 6], "sigma_range": 1.0, "sigma_lateral": 0.7}
        )
        put_json(
            s,
            f"mumt/{mission}/threat/e2",
            {"position": [7, 3], "sigma_range": 1.0, "sigma_lateral": 0.7, "facing_deg": 90, "ttl_s": 600},
        )
        scout = Unit(s, mission, "scout")
        put_json(s, f"mumt/{mission}/unit/scout/goal", {"position": [10, 10]})
        time.sleep(0.2)
        assert scout.report()["status"] in ("en_route", "escaping")
        idle = Unit(s, mission, "idle", pos=(1.0, 1.0))
        assert idle.report()["status"] == "no_goal"
        # then keep-out zones away from the units' ways: a polygon with a hole, and a circle with a TTL
        put_json(
            s,
            f"mumt/{mission}/zone/mines",
            {
                "polygon": [
                    [[40, 40], [60, 40], [60, 50], [40, 50], [40, 40]],
                    [[44, 42], [48, 42], [48, 46], [44, 42]],
                ]
            },
        )
        put_json(
            s, f"mumt/{mission}/zone/pond", {"circle": {"centre": [-30, 20], "radius_m": 5}, "ttl_s": 600}
        )
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            (r,) = [r for r in s.get(f"mumt/{mission}/planner/planner/status", timeout=2.0) if r.ok]
            if json.loads(r.ok.payload.to_bytes())["zones"] == 2:
                break
            time.sleep(0.1)
        yield endpoint, mission


@pytest.mark.proc
def test_status_lists_units_and_threats_as_tables(world):
    endpoint, mission = world
    r = run_pfp("status", "--connect", endpoint, "--mission", mission, timeout=60)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert f"planner planner, mission {mission}: 2 units, 2 threats, 2 zones" in out
    # the live planners first: this one owns both units
    assert re.search(
        r"^planner\s+owns\s+units\s+stale\s+threats\s+zones\s+p50\s+p99\s+deliberating\s+overload$", out, re.M
    )
    assert re.search(r"^planner\s+2\s+2\s+0\s+2\s+2\s", out, re.M), out
    assert re.search(r"^unit\s+kind\s+phase\s+status\s+last seen\s+to goal\s+position$", out, re.M)
    assert re.search(r"^idle\s+-\s+no_goal\s+no_goal\s+[\d.]+ s ago\s+-\s+\(1\.0, 1\.0\)$", out, re.M), out
    assert re.search(
        # with keep-out zones in force a unit's route may be in a worker (deliberating) when status asks
        r"^scout\s+-\s+(guided|deliberating)\s+(en_route|escaping)( \(deliberating\))?\s+[\d.]+ s ago\s+14\.1 m\s+\(0\.0, 0\.0\)$",
        out,
        re.M,
    ), out
    assert re.search(r"^threat\s+position\s+shape\s+TTL left$", out, re.M)
    assert re.search(r"^e1\s+\(4\.0, 6\.0\)\s+skew_normal 0°\s+no expiry$", out, re.M), out
    assert re.search(r"^e2\s+\(7\.0, 3\.0\)\s+skew_normal 90°\s+(5\d\d|600)\.\d s$", out, re.M), out
    assert re.search(r"^zone\s+kind\s+shape\s+centroid\s+TTL left$", out, re.M), out
    # the centroid of the polygon less its hole: (50 * 200 - 46.67 * 8) / 192, (45 * 200 - 43.33 * 8) / 192
    assert re.search(
        r"^mines\s+keep_out\s+polygon, 4 vertices, 1 hole\s+\(50\.1, 45\.1\)\s+no expiry$", out, re.M
    ), out
    assert re.search(
        r"^pond\s+keep_out\s+circle, radius 5\.0 m\s+\(-30\.0, 20\.0\)\s+(5\d\d|600)\.\d s$", out, re.M
    ), out


@pytest.mark.proc
def test_status_json_prints_the_full_lists(world):
    endpoint, mission = world
    r = run_pfp("status", "--connect", endpoint, "--mission", mission, "--json", timeout=60)
    assert r.returncode == 0, r.stderr
    (snap,) = json.loads(r.stdout)
    assert [u["id"] for u in snap["units"]] == ["idle", "scout"]
    assert snap["units"][1]["goal"] == [10.0, 10.0] and snap["units"][1]["distance_to_goal"] > 14
    assert [t["id"] for t in snap["threats"]] == ["e1", "e2"]
    assert snap["threats"][0]["ttl_s"] is None and 500 < snap["threats"][1]["ttl_s"] <= 600
    assert [z["id"] for z in snap["zones"]] == ["mines", "pond"] and snap["zones_total"] == 2
    assert snap["zones"][0]["zone"]["polygon"][1] == [[44.0, 42.0], [48.0, 42.0], [48.0, 46.0], [44.0, 42.0]]
    assert snap["zones"][1]["zone"]["circle"] == {"centre": [-30.0, 20.0], "radius_m": 5.0}
    assert 500 < snap["zones"][1]["ttl_s"] <= 600 and snap["next_zone"] is None


@pytest.mark.proc
def test_status_and_health_of_a_mission_nobody_plans_exit_1(world):
    endpoint, _ = world
    for command in ("status", "health"):
        r = run_pfp(command, "--connect", endpoint, "--mission", "nobody", "--timeout", "0.5", timeout=60)
        assert r.returncode == 1
        assert r.stderr.strip() == f"pfp {command}: no planner of mission 'nobody' answered within 0.5 s"


@pytest.mark.proc
def test_health_prints_rounded_figures_and_json_for_scripts(world):
    endpoint, mission = world
    r = run_pfp("health", "--connect", endpoint, "--mission", mission, timeout=60)
    assert r.returncode == 0 and "None" not in r.stdout
    assert re.fullmatch(
        r"planner ok: mission \w+, up [\d.]+ s, 2 units \(\d stale\), 2 threats, 2 zones; messages in \d+, out \d+, "
        r"rejected \d+; latency p50 (\d+\.\d\d ms|-), p99 (\d+\.\d\d ms|-)\n",
        r.stdout,
    ), r.stdout
    r = run_pfp("health", "--connect", endpoint, "--mission", mission, "--json", timeout=60)
    (status,) = json.loads(r.stdout)
    assert status["planner"] == "planner" and status["units"] == 2 and status["threats"] == 2


@pytest.mark.proc
def test_status_json_merges_every_page_of_a_big_world():
    """1,050 threats are two pages of the world reply: --json has them all, the tables the first page."""
    mission = "p" + uuid.uuid4().hex[:10]
    with planner_process("--escape", "none", mission=mission) as (endpoint, _), client(endpoint) as s:
        for j in range(1050):
            put_json(
                s,
                f"mumt/{mission}/threat/t{j:04d}",
                {"position": [100.0 + j, 50.0], "sigma_range": 1.0, "sigma_lateral": 0.7},
            )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            (r,) = [r for r in s.get(f"mumt/{mission}/planner/planner/status", timeout=2.0) if r.ok]
            if json.loads(r.ok.payload.to_bytes())["threats"] == 1050:
                break
            time.sleep(0.2)
        r = run_pfp("status", "--connect", endpoint, "--mission", mission, "--json", timeout=60)
        assert r.returncode == 0, r.stderr
        (snap,) = json.loads(r.stdout)
        assert [t["id"] for t in snap["threats"]] == [f"t{j:04d}" for j in range(1050)]
        assert snap["next_threat"] is None and snap["threats_total"] == 1050
        r = run_pfp("status", "--connect", endpoint, "--mission", mission, timeout=60)
        assert r.returncode == 0, r.stderr
        assert "... and 50 more threats (--json lists them all)" in r.stdout, r.stdout[-500:]
