"""``pfp map`` at its edges: flags, an unreachable router, a port in use, and the HTTP API without a browser."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
import uuid
from typing import Any

import pytest
import zenoh

from pfp_service.wire import keys
from tests.browser.test_map_browser import map_process
from tests.conftest import ROOT, run_pfp
from tests.zenoh_util import Inbox, client, free_port, put_json


@pytest.fixture
def router():
    """A bare Zenoh router on a free loopback port (no planner): the map needs only the keys."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    try:
        yield endpoint
    finally:
        session.close()


def _one_line_exit_2(r: subprocess.CompletedProcess[str]) -> str:
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    return r.stderr.strip()


@pytest.mark.proc
@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--http", "8080"], "--http: expected HOST:PORT"),
        (["--http", "127.0.0.1:99999"], "--http: expected HOST:PORT"),
        (["--push-hz", "50"], "--push-hz: must be at most 10"),
        (["--push-hz", "0"], "--push-hz: must be a finite number > 0"),
        (["--origin", "91,0"], "--origin:"),
        (["--mission", "a/b"], "--mission:"),
        (["--tiles", "http://tiles/{z}/{x}/{y}.png"], "--tiles: tiles need --origin"),
    ],
)
def test_bad_flags_are_one_line_exit_2(args, fragment):
    line = _one_line_exit_2(run_pfp("map", *args, "--connect", f"tcp/127.0.0.1:{free_port()}", timeout=60))
    assert fragment in line and line.startswith("pfp map"), line


@pytest.mark.proc
def test_no_router_is_one_line():
    r = run_pfp("map", "--connect", f"tcp/127.0.0.1:{free_port()}", "--http", "127.0.0.1:0", timeout=60)
    line = _one_line_exit_2(r)
    assert line.startswith("pfp map: --connect:"), line


@pytest.mark.proc
def test_a_port_in_use_is_one_line(router):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        line = _one_line_exit_2(
            run_pfp("map", "--connect", router, "--http", f"127.0.0.1:{port}", timeout=60)
        )
    assert line.startswith(f"pfp map: --http: cannot listen on 127.0.0.1:{port}"), line


@pytest.mark.unit
def test_every_flag_has_help_and_shows_its_default():
    from pfp_service.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    p = sub.choices["map"]  # type: ignore[index]
    formatter = p._get_formatter()
    for action in p._actions:
        if not action.option_strings or action.dest == "help":
            continue
        assert action.help, action.option_strings
        if action.default not in (None, False):
            assert "default" in (formatter._get_help_string(action) or ""), action.option_strings


def _http(method: str, url: str, body: Any = None, headers: dict[str, str] | None = None) -> tuple[int, Any]:
    data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
    req = urllib.request.Request(url, data=data, method=method, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


EDIT = {"X-PFP-Edit": "1", "Content-Type": "application/json"}


@pytest.mark.proc
def test_the_api_puts_through_the_same_keys_and_validates_first(router):
    mission = "api" + uuid.uuid4().hex[:8]
    with client(router) as s:
        # subscribed before the map's session opens: the router hands our subscribers to it
        # as it joins, so its first put cannot go out before it knows we listen
        threats = Inbox(s, keys.threats(mission))
        goals = Inbox(s, keys.goals(mission))
        with map_process(router, mission, "--allow-edit") as url:
            _puts_through_and_validates(s, url, mission, threats, goals)


def _puts_through_and_validates(s, url: str, mission: str, threats: Inbox, goals: Inbox) -> None:
    t = {"position": [3, 4], "sigma_range": 2, "sigma_lateral": 1, "facing_deg": 90, "ttl_s": 30}
    assert _http("PUT", url + "api/threat/t1", t, EDIT) == (
        200,
        {"ok": True, "key": keys.threat(mission, "t1")},
    )
    assert threats.get(timeout=5)["sigma_range"] == 2
    code, body = _http("DELETE", url + "api/threat/t1", None, EDIT)
    assert code == 200 and threats.get(timeout=5) is None  # a DELETE, as pfp inject's remove_threat
    assert _http("PUT", url + "api/goal/u1", {"position": [9, 9]}, EDIT)[0] == 200
    assert goals.get(timeout=5)["position"] == [9, 9]
    assert _http("DELETE", url + "api/goal/u1", None, EDIT)[0] == 200
    assert goals.get(timeout=5) is None

    # refused before anything is sent: a bad field names its path, a bad id its chunk
    code, body = _http(
        "PUT", url + "api/threat/t2", {"position": [1, "x"], "sigma_range": 1, "sigma_lateral": 1}, EDIT
    )
    assert code == 400 and body["field"] == "$.position[1]"
    code, body = _http(
        "PUT", url + "api/threat/t2", {"position": [1, 1], "sigma_range": 0, "sigma_lateral": 1}, EDIT
    )
    assert code == 400 and body["field"] == "$.sigma_range"
    code, body = _http("PUT", url + "api/threat/bad*id", t, EDIT)
    assert code == 400 and body["field"] == "threat"
    code, body = _http("PUT", url + "api/threat/t3", t, {"Content-Type": "application/json"})
    assert code == 403 and "X-PFP-Edit" in body["error"]  # another web page cannot send that header
    with pytest.raises(TimeoutError):
        threats.get(timeout=0.5)

    # the page, its script and the vendored Leaflet are served from the package
    for path in (
        "",
        "static/map.js",
        "static/vendor/leaflet/leaflet.js",
        "static/vendor/leaflet/LICENSE",
    ):
        with urllib.request.urlopen(url + path, timeout=10) as r:
            assert r.status == 200
    # no planner: a preview is news for the page, not an HTTP failure
    code, body = _http("GET", url + "api/preview/u1")
    assert code == 200 and body["error"] == "no planner of this mission answered"

    # what the map saw, as JSON
    put_json(s, keys.unit_state(mission, "u1"), {"position": [1, 2], "kind": "manned"})
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        state = _http("GET", url + "api/state")[1]
        if "u1" in state["units"] and state["units"]["u1"]["position"] == [1, 2]:
            break
        time.sleep(0.1)
    else:
        raise AssertionError(state)
    assert state["units"]["u1"]["goal"] is None and state["config"]["allow_edit"] is True
    stats = _http("GET", url + "api/stats")[1]
    assert stats["samples_in"] >= 5 and stats["backlog"] == 0


@pytest.mark.proc
def test_the_map_runs_from_a_plain_install_as_a_separate_process():
    r = subprocess.run(
        [sys.executable, "-m", "pfp_service", "map", "--help"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert r.returncode == 0 and "--allow-edit" in r.stdout


@pytest.mark.net
def test_the_map_embeds_in_another_program_on_its_own_thread(router):
    """What ``pfp demo --map`` needs: start, get the URL, keep running, close cleanly."""
    from pfp_clients.map.embed import MapThread
    from pfp_clients.map.server import MapOptions

    from pfp_service.node.config import client_zenoh_config

    mission = "emb" + uuid.uuid4().hex[:8]
    with (
        client(router) as s,
        MapThread(client_zenoh_config([router]), MapOptions(mission=mission, port=0)) as url,
    ):
        assert url.startswith("http://127.0.0.1:")
        put_json(s, keys.unit_state(mission, "e1"), {"position": [4, 5]})
        deadline = time.monotonic() + 5
        while "e1" not in _http("GET", url + "api/state")[1]["units"]:
            assert time.monotonic() < deadline
            time.sleep(0.1)
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(url + "api/state", timeout=2)  # closed with the block


@pytest.mark.net
def test_an_embedded_map_that_cannot_start_raises_in_the_caller():
    from pfp_clients.map.embed import MapThread
    from pfp_clients.map.server import MapOptions

    from pfp_service.node.config import client_zenoh_config

    with pytest.raises(Exception, match=r"(?i)connect|unable"):
        # a generous wait: on a loaded machine the failure to connect, not a timeout, must be what comes back
        MapThread(
            client_zenoh_config([f"tcp/127.0.0.1:{free_port()}"]), MapOptions(port=0), ready_timeout_s=120
        ).start()


@pytest.mark.multi
def test_the_map_learns_the_planners_origin_as_the_fleet_does():
    from tests.zenoh_util import planner_process

    mission = "org" + uuid.uuid4().hex[:8]
    with planner_process("--origin", "58.4105,15.6213", mission=mission) as (endpoint, _):
        with client(endpoint) as s:  # the planner answers its status once it is up
            deadline = time.monotonic() + 30
            while not any(r.ok for r in s.get(keys.planner_statuses(mission), timeout=2.0)):
                assert time.monotonic() < deadline, "no planner status"
        with map_process(endpoint, mission) as url:
            code, state = _http("GET", url + "api/state")
    assert code == 200
    assert state["config"]["origin"]["lat"] == pytest.approx(58.4105)
    assert state["config"]["origin"]["lon"] == pytest.approx(15.6213)
