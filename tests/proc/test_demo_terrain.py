"""``pfp demo --terrain`` as a user runs it: tracked vehicles over the Jacksboro sample DEM, the live planner over terrain."""

from __future__ import annotations

import pytest

from tests.conftest import run_pfp

pytestmark = pytest.mark.proc


def test_the_terrain_demo_crosses_real_ground_and_every_expectation_holds(tmp_path):
    out = tmp_path / "demo.png"
    r = run_pfp("demo", "--terrain", "--speed-up", "40", "--out", str(out), timeout=240)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    text = r.stdout
    assert "terrain: jacksboro.tif, planned for tracked vehicles" in text
    assert "add threat e3" in text  # the pop-up struck mid-route
    header = "unit  kind      status   time s  path m  exposure in view  min clear m"
    assert header in text
    rows = [line.split() for line in text.split(header, 1)[1].splitlines()[1:5]]
    assert sorted(row[0] for row in rows) == ["m1", "m2", "r1", "r2"]
    for row in rows:
        assert row[2] == "arrived" and float(row[4]) > 3000.0  # kilometres over the ridges
    assert "4/4 expectations held" in text
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_dem_that_is_no_dem_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "notadem.tif"
    bad.write_bytes(b"not a raster at all")
    r = run_pfp("demo", "--terrain", str(bad), "--out", str(tmp_path / "x.png"), timeout=60)
    assert r.returncode == 2, r.stdout[-2000:] + r.stderr[-2000:]
    assert "notadem.tif" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
