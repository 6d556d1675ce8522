"""``pfp map`` in a real headless Chromium (Debian's package, driven by Playwright) against real processes.

A planner (``pfp serve``), a fleet (``pfp fleet``), an inject script (``pfp
inject``) and the map (``pfp map``) each run as a subprocess on loopback with
a free port; this test only watches the page and, for the checks that need a
precise moment, puts or withdraws a sample itself.  The browser is the system
Chromium (``make test`` installs it when missing and running as root); where
``CI`` is set a missing browser fails the test instead of skipping it.
"""

from __future__ import annotations

import json
import math
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from pfp_service.wire import keys
from tests.conftest import ROOT
from tests.zenoh_util import Inbox, client, planner_process, put_json

pytestmark = [pytest.mark.browser, pytest.mark.alone]

CHROMIUM = os.environ.get("PFP_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def _need(what: str) -> None:
    if os.environ.get("CI"):
        pytest.fail(f"{what} (CI is set: the browser tests must run, `make test` installs it as root)")
    pytest.skip(what)


@pytest.fixture(scope="module")
def playwright() -> Iterator[Any]:
    if not os.path.exists(CHROMIUM):
        _need(f"no Chromium at {CHROMIUM}: apt-get install chromium")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _need("playwright is not installed (it is in the dev extra)")
    with sync_playwright() as p:
        yield p


class Page:
    """One page in a fresh browser profile, collecting console errors and uncaught exceptions."""

    def __init__(self, playwright: Any, url: str) -> None:
        self.profile = tempfile.mkdtemp(prefix="pfp-map-chromium-")
        self.context = playwright.chromium.launch_persistent_context(
            self.profile,
            executable_path=CHROMIUM,
            headless=True,
            args=CHROMIUM_ARGS,
            viewport={"width": 1280, "height": 800},
        )
        self.errors: list[str] = []
        self.page = self.context.new_page()
        self.page.on("console", lambda m: m.type == "error" and self.errors.append(m.text))
        self.page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))
        self.page.goto(url)
        self.wait("() => window.pfpMap && window.pfpMap.map !== null")

    def js(self, expression: str, arg: Any = None) -> Any:
        return self.page.evaluate(expression, arg)

    def wait(self, predicate: str, arg: Any = None, timeout_s: float = 10.0) -> None:
        """Wait for ``predicate`` in the page; on a timeout, say what the page logged."""
        from playwright.sync_api import TimeoutError as PlaywrightTimeout

        try:
            self.page.wait_for_function(predicate, arg=arg, timeout=timeout_s * 1000)
        except PlaywrightTimeout:
            raise AssertionError(
                f"not within {timeout_s} s: {predicate}; page errors: {self.errors}"
            ) from None

    def view(self, x0: float, y0: float, x1: float, y1: float) -> None:
        """Show mission metres ``[x0, x1] x [y0, y1]``, as an operator zooming there would."""
        self.js(
            "(b) => { pfpMap.userMoved = true; pfpMap.map.fitBounds(L.latLngBounds(b.map(toLatLng)), {animate: false}); }",
            [[x0, y0], [x1, y1]],
        )

    def click_at(self, x_m: float, y_m: float) -> None:
        """Click the map at mission metres (x east, y north)."""
        pt = self.js(
            "(p) => { const c = pfpMap.map.latLngToContainerPoint(toLatLng(p)); return [c.x, c.y]; }",
            [x_m, y_m],
        )
        box = self.page.locator("#map").bounding_box()
        self.page.mouse.click(box["x"] + pt[0], box["y"] + pt[1])

    def status_of(self, unit: str) -> str | None:
        return self.js(
            "(u) => { const el = document.querySelector(`[data-unit='${u}']`); return el && el.dataset.status; }",
            unit,
        )

    def close(self) -> None:
        self.context.close()
        shutil.rmtree(self.profile, ignore_errors=True)


@contextmanager
def page_at(playwright: Any, url: str) -> Iterator[Page]:
    page = Page(playwright, url)
    try:
        yield page
    finally:
        page.close()


def _pfp(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _stop(proc: subprocess.Popen[str]) -> str:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.stdout.read() if proc.stdout is not None and not proc.stdout.closed else ""


@contextmanager
def running(*args: str) -> Iterator[subprocess.Popen[str]]:
    proc = _pfp(*args)
    try:
        yield proc
    finally:
        _stop(proc)


@contextmanager
def map_process(endpoint: str, mission: str, *extra: str) -> Iterator[str]:
    """``pfp map`` on a free port; yields the page's URL once it serves (no ``endpoint``: ``extra`` says)."""
    connect = ["--connect", endpoint] if endpoint else []
    proc = _pfp("map", *connect, "--mission", mission, "--http", "127.0.0.1:0", *extra)
    lines: queue.Queue[str] = queue.Queue()
    assert proc.stdout is not None
    threading.Thread(target=lambda: [lines.put(ln) for ln in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
    seen: list[str] = []
    try:
        deadline = time.monotonic() + 60  # a fresh tree compiles numba caches; CI machines are busy
        url = None
        while url is None:
            try:
                line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise AssertionError(f"pfp map did not start: {seen}") from None
            seen.append(line)
            if " at http://" in line:
                url = line.split(" at ", 1)[1].split()[0]
        yield url
    finally:
        _stop(proc)


@pytest.fixture
def mission() -> str:
    return "map" + uuid.uuid4().hex[:8]


TEAM = """\
name: map-team
units:
  - {id: m1, kind: manned,   start: [0, 10],  goal: [60, 12], speed_mps: 1.0}
  - {id: r1, kind: unmanned, start: [0, 30],  goal: [60, 28], speed_mps: 1.2}
  - {id: u3, kind: unmanned, start: [5, 45],  speed_mps: 1.0}
"""

SCRIPT = """\
name: map-threats
duration_s: 60
timeline:
  - {do: add_threat, threat: e1, position: [30, 14], facing_deg: 270, sigma_range: 4, sigma_lateral: 3, skew: 2}
  - {do: add_threat, threat: e2, position: [34, 34], facing_deg: 250, sigma_range: 3, sigma_lateral: 2, skew: 1, ttl_s: 500}
"""


def _http(method: str, url: str, body: Any = None, headers: dict[str, str] | None = None) -> tuple[int, Any]:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(
        url, data=data, method=method, headers={"Content-Type": "application/json", **(headers or {})}
    )
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def _screenshot(page: Page, tmp_path: Path, name: str) -> Path:
    """Save a screenshot (and a copy where ``PFP_MAP_SCREENSHOT`` points, for the README)."""
    out = tmp_path / name
    page.page.screenshot(path=str(out))
    assert out.stat().st_size > 10_000
    wanted = os.environ.get("PFP_MAP_SCREENSHOT")
    if wanted and name == "map.png":
        shutil.copyfile(out, wanted)
    print(f"screenshot: {out}")
    return out


def test_the_map_shows_units_threats_staleness_and_a_preview(playwright, tmp_path, mission):
    team, script = tmp_path / "team.yaml", tmp_path / "inject.yaml"
    team.write_text(TEAM)
    script.write_text(SCRIPT)
    with (
        planner_process(mission=mission) as (endpoint, _planner),
        client(endpoint) as s,
        map_process(endpoint, mission, "--stale-s", "4") as url,
        page_at(playwright, url) as page,
    ):
        with running("inject", str(script), "--connect", endpoint, "--mission", mission) as inject:
            assert inject.wait(timeout=30) == 0, inject.stdout.read() if inject.stdout else ""
        with running(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission, "--duration-s", "300"
        ) as fleet:
            # one marker per unit, each with its kind and the planner's status
            page.wait("() => document.querySelectorAll('.unit-icon').length === 3")
            page.wait(
                "() => ['m1', 'r1', 'u3'].every((u) => { const el = document.querySelector(`[data-unit='${u}']`); return el && el.dataset.status !== 'unknown'; })"
            )
            # a unit's first report can beat its goal to the planner: no_goal, then on its way
            moving = "['en_route', 'escaping'].includes(document.querySelector(`[data-unit='${u}']`).dataset.status)"
            page.wait(f"() => ['m1', 'r1'].every((u) => {moving})")
            assert page.status_of("u3") == "no_goal"
            kinds = page.js(
                "() => Object.fromEntries([...document.querySelectorAll('.unit-icon')].map((e) => [e.dataset.unit, e.dataset.kind]))"
            )
            assert kinds == {"m1": "manned", "r1": "unmanned", "u3": "unmanned"}

            # a threat put appears within 1 s, its delete removes it within 1 s
            threat = {
                "position": [20, 40],
                "facing_deg": 90,
                "sigma_range": 2.0,
                "sigma_lateral": 1.5,
                "skew": 1,
                "ttl_s": 90,
            }
            t0 = time.monotonic()
            put_json(s, keys.threat(mission, "pop"), threat)
            page.wait("() => pfpMap.threats.has('pop')", timeout_s=1.0)
            shown_s = time.monotonic() - t0
            label = page.js("() => pfpMap.threats.get('pop').centre.getTooltip().getContent()")
            assert (
                label.startswith("pop · 1 min")
                or label.startswith("pop · 89")
                or label.startswith("pop · 90")
            ), label
            zone = page.js("() => pfpMap.threats.get('pop').data.zone.length")
            assert zone == 48
            # drawn from what the feed gives: zone, core, the shape's two arrow lines, the centre
            assert page.js("() => pfpMap.threats.get('pop').layers.length") == 5
            put_json(
                s,
                keys.threat(mission, "seen"),
                {"position": [-20, 40], "shape": "area", "params": {"radius_m": 3}},
            )
            page.wait("() => pfpMap.threats.has('seen')", timeout_s=2.0)
            assert page.js("() => pfpMap.threats.get('seen').layers.length") == 3  # an area faces no way
            s.delete(keys.threat(mission, "seen"))
            page.wait("() => !pfpMap.threats.has('seen')", timeout_s=2.0)
            t0 = time.monotonic()
            s.delete(keys.threat(mission, "pop"))
            page.wait("() => !pfpMap.threats.has('pop')", timeout_s=1.0)
            removed_s = time.monotonic() - t0
            print(f"threat shown after {shown_s * 1e3:.0f} ms, removed after {removed_s * 1e3:.0f} ms")

            # a unit that stops reporting and withdraws its token turns grey, with its age
            token = s.liveliness().declare_token(keys.alive_unit(mission, "ghost"))
            put_json(
                s,
                keys.unit_state(mission, "ghost"),
                {"position": [50, 50], "kind": "manned", "speed_mps": 1.0},
            )
            page.wait("() => document.querySelector(`[data-unit='ghost']`) !== null")
            assert page.status_of("ghost") != "stale"
            token.undeclare()
            page.wait(
                "() => document.querySelector(`[data-unit='ghost']`).dataset.status === 'stale'", timeout_s=8
            )
            assert page.js(
                "() => document.querySelector(`[data-unit='ghost'] .label`).textContent"
            ).startswith("ghost · ")

            # click a unit: its preview route and metrics
            page.page.click("[data-unit='m1']")
            page.wait("() => document.querySelector('#preview').dataset.state === 'ok'", timeout_s=10)
            text = page.page.inner_text("#preview")
            for what in ("length", "exposure", "min clearance", "ETA", "reason"):
                assert what in text
            assert "at 1.0 m/s" in text  # the ETA uses the unit's reported speed
            assert page.js("() => pfpMap.preview.preview.path.length") > 2
            assert page.js("() => pfpMap.layers.preview.getLayers().length") == 1

            # the inject script's threats, with zones, cores and the TTL of the one that has one
            assert sorted(page.js("() => [...pfpMap.threats.keys()]")) == ["e1", "e2"]
            assert page.js("() => pfpMap.threats.get('e1').data.core.length") == 48
            assert page.js("() => pfpMap.threats.get('e1').data.expires_at") is None
            assert (
                page.js(
                    "() => pfpMap.threats.get('e2').data.expires_at - pfpMap.threats.get('e2').data.put_at"
                )
                == 500
            )
            # the planner's status panel
            page.wait("() => document.querySelector('#status').innerText.includes('p99')")
            status = page.page.inner_text("#status")
            assert "threats" in status and "rejected" in status

            # a rejected input is aggregated in the feed
            for _ in range(3):
                s.put(keys.unit_state(mission, "bad"), b'{"position": [1, "x"]}')
            page.wait(
                "() => document.querySelector('#rejected li') && document.querySelector('#rejected li').dataset.count === '3'"
            )

            # editing is off: the API refuses
            code, body = _http(
                "PUT",
                url + "api/threat/x1",
                {"position": [1, 1], "sigma_range": 1, "sigma_lateral": 1},
                {"X-PFP-Edit": "1"},
            )
            assert code == 403 and "allow-edit" in body["error"]
            assert page.js("() => document.querySelector('#edit-panel').hidden") is True

            _screenshot(page, tmp_path, "map.png")
            assert page.errors == []

            # a map started late learns what was put before it from the planner's world query
            with map_process(endpoint, mission) as late_url, page_at(playwright, late_url) as late:
                late.wait("() => pfpMap.threats.has('e1') && pfpMap.threats.has('e2')", timeout_s=5)
                ttl_left = late.js("() => pfpMap.threats.get('e2').data.expires_at - pfpMap.state_now()")
                assert 400 < ttl_left < 500  # the TTL left, not the TTL put
                late.wait("() => ['m1', 'r1', 'u3'].every((u) => pfpMap.units.has(u))")
                assert late.errors == []
            assert fleet.poll() is None


def test_allow_edit_drops_moves_and_deletes_a_threat_and_sets_a_goal(playwright, tmp_path, mission):
    team = tmp_path / "team.yaml"
    team.write_text("units:\n  - {id: a1, kind: unmanned, start: [0, 20], goal: [80, 20], speed_mps: 1.0}\n")
    with (
        planner_process(mission=mission) as (endpoint, _planner),
        client(endpoint) as s,
        running(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission, "--duration-s", "300"
        ),
        map_process(endpoint, mission, "--allow-edit") as url,
        page_at(playwright, url) as page,
    ):
        directions = Inbox(s, keys.unit_direction(mission, "a1"))
        replans = Inbox(s, keys.event(mission, "replan"))
        page.wait("() => document.querySelector(`[data-unit='a1']`) !== null")
        page.view(-5, -5, 85, 65)
        before = directions.get(timeout=10, where=lambda d: d["status"] == "en_route")
        assert before["vector"][0] > 0.99  # nothing in the way: straight east

        # drop a threat right ahead of the unit, by clicking
        page.page.fill("#new-id", "drop1")
        page.page.fill("#new-facing", "270")
        page.page.fill("#new-sr", "4")
        page.page.fill("#new-sl", "3")
        page.page.click("#threat-drop")
        x_now = page.js("() => pfpMap.units.get('a1').data.position[0]")
        page.click_at(x_now + 12, 21)
        page.wait("() => pfpMap.threats.has('drop1')", timeout_s=3)
        replan = replans.get(timeout=5)
        assert "a1" in replan["units"]
        turned = directions.get(timeout=5, where=lambda d: abs(d["vector"][1]) > 0.05)
        assert math.hypot(*turned["vector"]) == pytest.approx(1.0, abs=1e-6)  # the planner steers round it
        drop = page.js("() => pfpMap.threats.get('drop1').data")
        assert (
            drop["update"]["facing_deg"] == 270
            and drop["update"]["sigma_range"] == 4
            and drop["position"][1] == pytest.approx(21, abs=0.5)
        )

        # select it by clicking its centre, move it away, then delete it
        page.click_at(*drop["position"])
        page.wait("() => !document.querySelector('#threat-panel').hidden")
        page.page.click("#threat-move")
        page.click_at(x_now + 12, 60)
        page.wait(
            "() => pfpMap.threats.get('drop1') && pfpMap.threats.get('drop1').data.position[1] > 55",
            timeout_s=3,
        )
        page.page.click("#threat-delete")
        page.wait("() => !pfpMap.threats.has('drop1')", timeout_s=3)

        # set the unit's goal by clicking, then cancel it
        page.page.click("[data-unit='a1']")
        page.page.click("#goal-set")
        page.click_at(40, 45)
        page.wait(
            "() => { const g = pfpMap.units.get('a1').data.goal; return g && Math.abs(g[1] - 45) < 0.5; }",
            timeout_s=3,
        )
        directions.get(timeout=5, where=lambda d: d["vector"][1] > 0.3)  # now heading north-east
        # the selected unit's preview follows its new goal by itself
        page.wait(
            "() => { const p = pfpMap.preview && pfpMap.preview.preview; if (!p) return false;"
            " const e = p.path[p.path.length - 1]; return Math.hypot(e[0] - 40, e[1] - 45) < 1; }",
            timeout_s=8,
        )
        page.page.click("#goal-cancel")
        directions.get(timeout=5, where=lambda d: d["status"] == "no_goal")
        page.wait("() => pfpMap.units.get('a1').data.goal === null", timeout_s=3)

        _screenshot(page, tmp_path, "map-edit.png")
        assert page.errors == []
