"""``pfp map`` under the shipped ACL (``pfp acl``): it sees the mission as an observer and edits as reporter and commander.

A router opened from the generated user/password config, a real planner as
the ``planner`` principal, a unit as ``unit-u1``, and the map as ``injector``
(observer, reporter and commander) through ``--zenoh-config``; an ``observer``
map may look but its edits never reach the mission.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import zenoh

from pfp_service.cli import main as pfp_main
from tests.browser.test_map_browser import map_process
from tests.proc.test_map_cli import EDIT, _http
from tests.zenoh_util import Inbox, free_port, put_json

M = "mapacl"
TEAM = "name: map-acl\nunits:\n  - {id: u1, start: [0, 0], goal: [10, 0]}\n"


@pytest.fixture(scope="module")
def acl(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mapacl")
    port = free_port()
    (tmp / "team.yaml").write_text(TEAM)
    out = tmp / "acl"
    argv = ["acl", str(tmp / "team.yaml"), "--out", str(out), "--mission", M, "--quiet"]
    assert pfp_main([*argv, "--listen", f"tcp/127.0.0.1:{port}", "--connect-host", f"127.0.0.1:{port}"]) == 0
    router = zenoh.open(zenoh.Config.from_file(str(out / "zenoh-router.json5")))
    try:
        yield out
    finally:
        router.close()


def _as(out: Path, name: str) -> zenoh.Session:
    return zenoh.open(zenoh.Config.from_file(str(out / "clients" / f"{name}.json5")))


def _state(url: str) -> dict:
    return _http("GET", url + "api/state")[1]


@pytest.mark.proc
def test_the_map_as_injector_sees_the_unit_and_edits_through_the_acl(acl):
    from pfp_service.node.config import ServeConfig
    from pfp_service.node.node import PlannerNode

    planner = _as(acl, "planner")
    unit = _as(acl, "unit-u1")
    observer = _as(acl, "observer")
    # The preview's budget is generous: this test is of the ACL, and under a loaded CI a first preview's
    # route search took the default 500 ms, its walk cut at its first check (64 steps, at (3.94, -1.97)).
    conf = ServeConfig(mission=M, planner_id="planner", mode="client", preview_budget_ms=10_000.0)
    node = PlannerNode(planner, conf)
    node.start()
    try:
        token = unit.liveliness().declare_token(f"mumt/{M}/alive/unit/u1")
        threats = Inbox(observer, f"mumt/{M}/threat/*")
        with map_process(
            "", M, "--zenoh-config", str(acl / "clients" / "injector.json5"), "--allow-edit"
        ) as url:
            deadline = time.monotonic() + 10
            while "u1" not in _state(url)["units"]:
                put_json(unit, f"mumt/{M}/unit/u1/state", {"position": [0.0, 0.0], "kind": "unmanned"})
                assert time.monotonic() < deadline, "the map never saw u1 through the ACL"
                time.sleep(0.2)
            # reporter: a threat put from the page reaches the mission
            t = {"position": [5, 1], "sigma_range": 1, "sigma_lateral": 1}
            assert _http("PUT", url + "api/threat/x1", t, EDIT)[0] == 200
            assert threats.get(timeout=5)["position"] == [5, 1]
            # commander: a goal from the page, then the planner's preview of the unit
            assert _http("PUT", url + "api/goal/u1", {"position": [10, 2]}, EDIT)[0] == 200
            deadline = time.monotonic() + 10
            while True:
                put_json(unit, f"mumt/{M}/unit/u1/state", {"position": [0.0, 0.0], "kind": "unmanned"})
                body = _http("GET", url + "api/preview/u1")[1]
                if "preview" in body:
                    break
                assert time.monotonic() < deadline, body
                time.sleep(0.3)
            p = body["preview"]  # its status and reason name a walk cut short, if one ever is
            assert p["path"][-1] == pytest.approx([10, 2], abs=0.5), {
                k: p.get(k) for k in ("status", "reason", "steps", "escapes", "events", "compute_ms")
            }
            deadline = time.monotonic() + 10
            while (
                _state(url)["status"].get("planner", {}).get("units") != 1
            ):  # observer: the planner's status
                assert time.monotonic() < deadline, _state(url)["status"]
                time.sleep(0.2)
        # an observer-only map: it looks, but the router drops its edits
        with map_process(
            "", M, "--zenoh-config", str(acl / "clients" / "observer.json5"), "--allow-edit"
        ) as url:
            deadline = time.monotonic() + 10
            while "planner" not in _state(url)["status"]:  # the planners' status: an observer may ask
                assert time.monotonic() < deadline
                time.sleep(0.2)
            assert "x1" in _state(url)["threats"]  # an observer asks the planner's world at start
            t2 = {"position": [7, 7], "sigma_range": 1, "sigma_lateral": 1}
            assert _http("PUT", url + "api/threat/x2", t2, EDIT)[0] == 200  # a put is fire-and-forget
            with pytest.raises(TimeoutError):
                threats.get(timeout=1.0, where=lambda m: m is not None and m.get("position") == [7, 7])
        token.undeclare()
    finally:
        node.stop()
        for s in (observer, unit, planner):
            s.close()
