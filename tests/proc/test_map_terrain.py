"""``pfp map --terrain DEM``: the hillshade overlay and a clicked threat's viewshed, as a user sees them.

The map runs as a subprocess over a bare Zenoh router; the page is Debian's
headless Chromium (``test_map_browser``'s launcher).  The viewshed the page
draws is read back from the page's own image and compared, pixel by pixel,
with an exact ray (Franklin's R3) cast on the DEM's cells from the threat.
"""

from __future__ import annotations

import base64
import io
import math
import time

import numpy as np
import pytest

from pfp_service.wire import keys
from tests.browser.test_map_browser import _screenshot, map_process, page_at, playwright  # noqa: F401 - a fixture
from tests.conftest import run_pfp
from tests.proc.test_map_cli import _one_line_exit_2, router  # noqa: F401 - a fixture
from tests.terrain_data import jacksboro, observers, write_geographic
from tests.zenoh_util import client, free_port, put_json


def _png(data_url: str) -> np.ndarray:
    from PIL import Image

    head = "data:image/png;base64,"
    assert data_url.startswith(head)
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(data_url[len(head) :]))).convert("RGBA"))


def _pixel_centres(bounds: list[list[float]], rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Where Leaflet puts each pixel of an image over ``[[s, w], [n, e]]``: linear in Web Mercator."""
    (s, w), (n, e) = bounds
    y = lambda lat: math.log(math.tan(math.pi / 4 + math.radians(lat) / 2))
    ys = y(n) + (np.arange(rows) + 0.5) * (y(s) - y(n)) / rows
    return np.degrees(2 * np.arctan(np.exp(ys)) - np.pi / 2), w + (np.arange(cols) + 0.5) * (e - w) / cols


@pytest.mark.proc
@pytest.mark.parametrize(
    ("content", "fragment"),
    [(None, "cannot read"), ("not a raster\n", "is not a DEM")],
)
def test_a_bad_dem_is_one_line_exit_2(tmp_path, content, fragment):
    dem = tmp_path / "bad.tif"
    if content is not None:
        dem.write_text(content)
    r = run_pfp("map", "--terrain", str(dem), "--connect", f"tcp/127.0.0.1:{free_port()}", timeout=60)
    line = _one_line_exit_2(r)
    assert str(dem) in line and fragment in line, line


@pytest.mark.browser
@pytest.mark.alone
def test_the_map_shades_the_ground_and_shows_a_clicked_threats_viewshed(playwright, router, tmp_path):  # noqa: F811
    from pfp_service.geo import Origin
    from pfp_service.terrain.viewshed import exact_lowest_visible_height

    dem = write_geographic(tmp_path / "jacksboro.tif")
    z, west, north, step = jacksboro()
    rows, cols = z.shape
    south, east = north - rows * step, west + cols * step
    centre = Origin(lat=(south + north) / 2, lon=(west + east) / 2)
    ridge = observers(z.astype(float), 60)["ridge"]
    t_lat, t_lon = north - (ridge[0] + 0.5) * step, west + (ridge[1] + 0.5) * step
    tx, ty = centre.to_local(t_lat, t_lon)
    mission = "terrain" + str(free_port())
    with (
        client(router) as s,
        map_process(router, mission, "--terrain", str(dem), "--origin", f"{centre.lat},{centre.lon}") as url,
        page_at(playwright, url) as page,
    ):
        # the hillshade: an image over the DEM's own corners, under the shapes, toggled off and on
        page.wait("() => pfpTerrain.shade !== null && document.querySelector('img.terrain-shade') !== null")
        b = page.js(
            "() => { const b = pfpTerrain.shade.layer.getBounds(); return [b.getSouth(), b.getWest(), b.getNorth(), b.getEast()]; }"
        )
        assert b == pytest.approx([south, west, north, east], abs=1e-6)
        shade = _png(page.js("() => pfpTerrain.shade.data.image"))
        assert shade.shape[:2] == (rows, cols)  # one pixel a DEM cell
        # opaque but for a rim of about two cells: the outer half cell (beyond the outer centres
        # the reader knows no ground) and the planar grid's cell inside it; and shaded
        assert (shade[3:-3, 3:-3, 3] == 255).all() and shade[..., 0].std() > 10
        toggle = page.page.locator("#terrain-layers input[type=checkbox]").first
        toggle.click()
        page.wait("() => !pfpMap.map.hasLayer(pfpTerrain.shade.layer)")
        toggle.click()
        page.wait("() => pfpMap.map.hasLayer(pfpTerrain.shade.layer)")

        # a threat on the ridge; click it: its viewshed comes as a second image
        threat = {
            "position": [round(tx, 2), round(ty, 2)],
            "facing_deg": 90,
            "sigma_range": 1500,
            "sigma_lateral": 1200,
        }
        put_json(s, keys.threat(mission, "ridge"), threat)
        page.wait("() => pfpMap.threats.has('ridge')")
        page.view(tx - 6000, ty - 6000, tx + 6000, ty + 6000)
        page.click_at(tx, ty)
        page.wait(
            "() => pfpTerrain.viewshed !== null && document.querySelector('img.threat-viewshed') !== null",
            timeout_s=30,
        )
        assert "sees" in page.page.inner_text("#threat-viewshed")
        vs = page.js("() => pfpTerrain.viewshed.data")
        assert vs["observer_height_m"] == 2.0 and vs["target_height_m"] == 1.8
        radius = vs["radius_m"]
        assert 3000 < radius <= 10_000  # the threat's reach, within the bound

        # every pixel of the page's image against an exact ray over the DEM's cells
        img = _png(vs["image"])
        lat, lon = _pixel_centres(vs["bounds"], *img.shape[:2])
        glat, glon = np.meshgrid(lat, lon, indexing="ij")
        r = np.floor((north - glat) / step).astype(int)
        c = np.floor((glon - west) / step).astype(int)
        dx, dy = (
            (centre.to_local(t_lat, t_lon + step)[0] - tx),
            (centre.to_local(t_lat + step, t_lon)[1] - ty),
        )
        dist = np.hypot((c - ridge[1]) * dx, (r - ridge[0]) * dy)
        on = (r >= 0) & (r < rows) & (c >= 0) & (c < cols) & (dist <= radius)
        # cells within a cell of the circle's edge: which side a cell falls is the sweep's rounding
        on &= np.abs(dist - radius) > max(dx, dy)
        cells = np.column_stack([r[on], c[on]])
        lowest = exact_lowest_visible_height(z.astype(float), ridge, 2.0, cells, dx, dy)
        exact = lowest <= 1.8
        drawn = img[..., 3][on] > 0
        agree = float((exact == drawn).mean())
        print(f"viewshed: {on.sum()} pixels, {exact.mean():.0%} seen by the exact ray, agreement {agree:.2%}")
        assert 0.05 < exact.mean() < 0.95  # a viewshed that can fail either way
        assert agree >= 0.97
        assert not (img[..., 3] > 0)[(r < 0) | (r >= rows) | (dist > radius + max(dx, dy))].any()

        _screenshot(page, tmp_path, "map-terrain.png")  # docs/map-terrain.png is one

        # another click on the map closes the threat, and its viewshed with it
        page.click_at(tx + 3000, ty + 3000)
        page.wait(
            "() => pfpTerrain.viewshed === null && document.querySelector('img.threat-viewshed') === null"
        )
        assert page.errors == []


@pytest.mark.proc
def test_the_terrain_api_answers_a_threat_off_the_dem_and_draws_from_the_dems_centre(router, tmp_path):  # noqa: F811
    import json
    import urllib.error
    import urllib.request

    dem = write_geographic(tmp_path / "jacksboro.tif")
    _z, west, north, step = jacksboro()
    mission = "terrain" + str(free_port())

    def get(url: str) -> tuple[int, dict]:
        try:
            with urllib.request.urlopen(url, timeout=30) as r:
                return r.status, json.loads(r.read())
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read())

    with client(router) as s, map_process(router, mission, "--terrain", str(dem)) as url:
        # no --origin and no planner: the DEM's centre
        _, state = get(url + "api/state")
        o = state["config"]["origin"]
        assert o["lat"] == pytest.approx(north - 172 * step, abs=1e-9)
        assert o["lon"] == pytest.approx(west + 201.5 * step, abs=1e-9)
        assert state["config"]["terrain"] == {"path": "jacksboro.tif"}
        assert get(url + "api/viewshed/nobody")[0] == 404
        put_json(
            s,
            keys.threat(mission, "far"),
            {"position": [90_000.0, 0.0], "sigma_range": 500, "sigma_lateral": 400},
        )
        for _ in range(100):
            code, body = get(url + "api/viewshed/far")
            if code == 200:
                break
            time.sleep(0.1)  # the map has not heard of it yet
        assert code == 200 and "outside the DEM" in body["error"], body
        code, shade = get(url + "api/terrain")
        assert code == 200 and shade["image"].startswith("data:image/png;base64,")
