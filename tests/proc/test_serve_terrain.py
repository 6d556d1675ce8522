"""``pfp serve --terrain DEM`` on real ground (the Jacksboro DEM): status, slope barriers, previews (issue 32).

A real planner subprocess plans over the DEM written to GeoTIFF
(``terrain_data``); a unit is guided over Zenoh, moving ``step`` along each
direction as a vehicle does.  Its track must never cross ground steeper
than its class allows (checked on the grid the planner places, cell by
cell), and the preview asked before it moved must be that track.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from pfp_service.terrain.planning import over_ground
from pfp_service.wire import decode_world_snapshot, keys
from pfp_service.wire.messages import decode_planner_status
from tests.terrain_data import write_geographic
from tests.zenoh_util import ROOT, Inbox, client, planner_process, put_json

pytestmark = pytest.mark.proc

# found on this DEM with the world in process: plain descent past the threat, no route search
START, GOAL, THREAT = (4593.0, 4639.0), (2363.0, 3985.0), (3229.0, 4128.0)


@pytest.fixture(scope="module")
def dem(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_geographic(tmp_path_factory.mktemp("dem") / "jacksboro.tif")


def test_a_bad_dem_is_refused_with_one_line_and_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "photo.tif"
    bad.write_bytes(b"not a raster at all\n" * 10)
    done = subprocess.run(
        [sys.executable, "-m", "pfp_service", "serve", "--terrain", str(bad), "--state-dir", "none"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and str(bad) in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def _snapshot(s, m: str):
    (reply,) = [r for r in s.get(keys.worlds(m), timeout=5) if r.ok is not None]
    return decode_world_snapshot(reply.ok.payload.to_bytes())


def _deliberations_landed(s, m: str, within_s: float = 60.0) -> None:
    deadline = time.monotonic() + within_s
    while True:
        (reply,) = [r for r in s.get(keys.planner_statuses(m), timeout=5) if r.ok is not None]
        if decode_planner_status(reply.ok.payload.to_bytes()).deliberating == 0:
            return
        assert time.monotonic() < deadline, f"deliberations still running after {within_s:g} s"
        time.sleep(0.05)


def test_serve_over_terrain_names_it_and_guides_a_unit_round_the_steep_ground(dem: Path) -> None:
    from pfp_service.terrain.barriers import barrier_cells
    from pfp_service.terrain.live import load

    m = "g" + uuid.uuid4().hex[:8]
    # the live searches' budget as the preview's: a loaded machine (two workers beside a load of 6) ran a
    # search past the default 5 s, the unit descended without it, and its track left the preview's
    args = ("--terrain", str(dem), "--state-dir", "none", "--preview-budget-ms", "20000")
    args += ("--deliberation-budget-s", "20")
    # and the threat held for its window of sight until it lands (the default 0.25 s puts it in force
    # blind first on a loaded machine; masked mid-route, the field then changed under the walk below)
    args += ("--sight-wait-s", "60")
    with planner_process(*args, mission=m) as (ep, _proc), client(ep) as s:
        (reply,) = [r for r in s.get(keys.planner_statuses(m), timeout=10) if r.ok is not None]
        st = decode_planner_status(reply.ok.payload.to_bytes())
        t = st.terrain
        assert t is not None and t.file == "jacksboro.tif" and t.unit == "foot" and t.origin_centred
        assert t.sha256 == hashlib.sha256(dem.read_bytes()).hexdigest()
        assert (t.south, t.west, t.north, t.east) == pytest.approx(
            (36.44625, -84.41375, 36.73292, -84.07792), abs=1e-4
        )
        assert 70.0 < t.resolution_m < 80.0  # 3 arc-seconds
        assert st.origin is not None  # the DEM's centre
        assert (st.origin.lat, st.origin.lon) == pytest.approx(
            ((t.south + t.north) / 2, (t.west + t.east) / 2)
        )

        put_json(
            s,
            keys.threat(m, "t1"),
            {"position": list(THREAT), "sigma_range": 600, "sigma_lateral": 400, "facing_deg": 0},
        )
        deadline = time.monotonic() + 60  # in force with its window: listed in the world's snapshot
        while not any(t.id == "t1" for t in _snapshot(s, m).threats):
            assert time.monotonic() < deadline, "t1 never took force"
            time.sleep(0.05)
        inbox = Inbox(s, keys.unit_direction(m, "u1"))
        pos, seq = START, 0

        def report() -> dict:
            nonlocal seq
            seq += 1
            put_json(s, keys.unit_state(m, "u1"), {"position": list(pos), "seq": seq})
            return inbox.get(timeout=20, where=lambda d: d.get("seq") == seq)  # type: ignore[no-any-return]

        assert report()["status"] == "no_goal"
        put_json(s, keys.unit_goal(m, "u1"), {"position": list(GOAL)})
        inbox.get(timeout=20, where=lambda d: d["status"] == "en_route")
        (got,) = list(s.get(keys.preview(m, "u1"), timeout=30))
        assert got.ok is not None, got.err.payload.to_bytes()
        pv = json.loads(got.ok.payload.to_bytes())
        assert pv["status"] == "reached", pv["reason"]
        step = pv["params"]["step"]
        track = [pos]
        for _ in range(2000):
            d = report()
            while d.get("deliberating"):  # the preview is the route once it has landed: hold until then
                _deliberations_landed(s, m)  # (a loaded machine's worker can take seconds; descending
                d = report()  # meanwhile, the track left the preview's)
            if d["status"] != "en_route":
                break
            move = min(step, d["distance_to_goal"]) if d.get("distance_to_goal") is not None else step
            pos = (pos[0] + move * d["vector"][0], pos[1] + move * d["vector"][1])
            track.append(pos)
        assert d["status"] == "arrived", d
        np.testing.assert_allclose(
            np.array(track), np.array(pv["path"]), atol=1e-6
        )  # the preview is the stream

    ground = load(str(dem), None, None, "foot")  # the grid the planner placed, at the same centre
    g = ground.grid
    steep, unknown = barrier_cells(g, ground.unit.max_slope_deg)
    pts = np.array(track)
    fine = np.concatenate([a + np.linspace(0, 1, 20)[:, None] * (b - a) for a, b in zip(pts[:-1], pts[1:])])
    i = np.floor((fine[:, 0] - g.x0_m) / g.cell_m).astype(int)
    k = np.floor((fine[:, 1] - g.y0_m) / g.cell_m).astype(int)
    assert not (steep[k, i] | unknown[k, i]).any()
    assert float(np.nanmax(g.slope_deg(fine[:, 0], fine[:, 1]))) <= ground.unit.max_slope_deg + 1e-9
    # the preview measured its path over the ground: elevations, and the ETA at the unit's own speed
    path = np.array(pv["path"])
    np.testing.assert_allclose(pv["path_elevation_m"], g.elevation(path[:, 0], path[:, 1]), atol=1e-6)
    assert pv["eta_s"] == pytest.approx(over_ground(g, path, ground.unit)["eta_s"], rel=1e-9)
    assert pv["length"] / 1.7 < pv["eta_s"] and pv["climb_m"] > 0.0  # Tobler: 1.68 m/s at its fastest
    print(
        f"over terrain: {len(track)} steps, steepest {np.nanmax(g.slope_deg(fine[:, 0], fine[:, 1])):.1f} deg"
    )
