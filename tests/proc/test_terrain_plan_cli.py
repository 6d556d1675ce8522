"""``pfp plan`` over terrain as a user runs it: the scenario's ``terrain:``, ``--terrain``, and bad DEMs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests import terrain_data
from tests.conftest import run_pfp

pytestmark = pytest.mark.proc

SCENARIO = """\
name: jacksboro
{terrain}
unit: {{class: foot}}
start: [-3000, -3000]
goal: [3000, 3000]
threats:
  - {{position: [0, 500], facing_deg: 200, sigma_range: 800, sigma_lateral: 600, skew: 1}}
  - {{position: [1500, -1000], facing_deg: 300, sigma_range: 700, sigma_lateral: 500, skew: 1}}
"""


@pytest.fixture(scope="module")
def ground(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("plan")
    terrain_data.write_geographic(d / "jacksboro.tif")
    (d / "with.yaml").write_text(SCENARIO.format(terrain="terrain: jacksboro.tif"))
    (d / "blind.yaml").write_text(SCENARIO.format(terrain=""))
    (d / "not-a-dem.tif").write_text("not a raster\n")
    return d


def _one_line_exit_2(result, *names: str) -> None:  # type: ignore[no-untyped-def]
    err = result.stderr.strip()
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr and len(err.splitlines()) == 1, result.stderr
    for name in names:
        assert name in err, (name, err)


def test_plan_over_the_scenarios_terrain_reports_the_ground(ground: Path) -> None:
    got = run_pfp("plan", str(ground / "with.yaml"), "--json", cwd="/")  # terrain: is relative to the file
    assert got.returncode == 0, got.stderr
    r = json.loads(got.stdout)
    assert r["status"] == "reached"
    assert len(r["path_elevation_m"]) == len(r["path"])
    assert all(236.0 <= z <= 1076.0 for z in r["path_elevation_m"])  # the DEM's range
    assert r["climb_m"] > 0 and 0 < r["max_slope_deg"] <= 30.0 and r["eta_s"] > r["length"] / 1.4 * 0.9
    assert [v["id"] for v in r["in_view"]] == ["t1", "t2"]
    assert r["exposure"] <= r["exposure_unmasked"]
    blind = json.loads(run_pfp("plan", str(ground / "blind.yaml"), "--json").stdout)
    assert blind["path_elevation_m"] is None and blind["exposure_unmasked"] is None
    # --terrain on the terrain-blind file gives the same plan as the file's terrain:
    flag = json.loads(
        run_pfp(
            "plan", str(ground / "blind.yaml"), "--terrain", str(ground / "jacksboro.tif"), "--json"
        ).stdout
    )
    assert flag["path"] == r["path"]
    text = run_pfp("plan", str(ground / "with.yaml")).stdout
    assert "terrain: climb" in text and "in view: t1" in text, text


def test_a_bad_dem_is_one_line_and_exit_2(ground: Path) -> None:
    _one_line_exit_2(
        run_pfp("plan", str(ground / "blind.yaml"), "--terrain", str(ground / "not-a-dem.tif")),
        "not-a-dem.tif",
    )
    _one_line_exit_2(
        run_pfp("plan", str(ground / "blind.yaml"), "--terrain", str(ground / "missing.tif")), "missing.tif"
    )
    far = ground / "far.yaml"
    far.write_text("origin: {lat: 10.0, lon: 10.0}\n" + SCENARIO.format(terrain="terrain: jacksboro.tif"))
    _one_line_exit_2(run_pfp("plan", str(far)), "jacksboro.tif", "cover")
