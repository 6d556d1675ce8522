"""``pfp serve`` configuration: precedence, one-line errors, joining a router, JSON logs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import uuid

import pytest
import zenoh

from pfp_service.errors import InputError
from pfp_service.node.config import DEFAULT_LISTEN, load_config, zenoh_config
from tests.conftest import ROOT, run_pfp
from tests.proc.test_serve import Unit
from tests.zenoh_util import client, free_port, put_json, wait_for_planner

pytestmark = pytest.mark.proc


def test_precedence_defaults_file_env_flags(tmp_path):
    toml = tmp_path / "pfp.toml"
    toml.write_text('mission = "from-file"\nunit_stale_s = 3.0\ndelta = 0.5\nconnect = ["tcp/127.0.0.1:1"]\n')
    cfg = load_config(toml, {}, {})
    assert (cfg.mission, cfg.unit_stale_s, cfg.delta, cfg.mode) == ("from-file", 3.0, 0.5, "router")
    env = {"PFP_MISSION": "from-env", "PFP_UNIT_STALE_S": "4.5", "PFP_CONNECT": "tcp/a:1, tcp/b:2"}
    cfg = load_config(toml, env, {})
    assert (cfg.mission, cfg.unit_stale_s, cfg.connect) == ("from-env", 4.5, ["tcp/a:1", "tcp/b:2"])
    cfg = load_config(toml, env, {"mission": "from-flag", "unit_stale_s": None})
    assert (cfg.mission, cfg.unit_stale_s, cfg.delta) == ("from-flag", 4.5, 0.5)
    assert load_config(None, {}, {}).planner_params().escape == "auto"


def test_errors_name_the_source(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("unit_stale_s = -1\n")
    with pytest.raises(InputError, match=r"bad\.toml: unit_stale_s: must be > 0"):
        load_config(bad, {}, {})
    with pytest.raises(InputError, match=r"^PFP_DELTA: "):
        load_config(None, {"PFP_DELTA": "lots"}, {})
    with pytest.raises(InputError, match=r"^PFP_MODE: unknown value 'mesh'"):
        load_config(None, {"PFP_MODE": "mesh"}, {})
    bad.write_text("nonsense = 1\n")
    with pytest.raises(InputError, match="nonsense: unknown field"):
        load_config(bad, {}, {})
    bad.write_text("mission = [\n")
    with pytest.raises(InputError, match="invalid TOML"):
        load_config(bad, {}, {})


def test_zenoh_config_defaults_to_the_embedded_router():
    conf = zenoh_config(load_config(None, {}, {}))
    assert json.loads(conf.get_json("listen/endpoints")) in ([DEFAULT_LISTEN], {"router": [DEFAULT_LISTEN]})
    assert json.loads(conf.get_json("mode")) == "router"
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    sizes = json.loads(conf.get_json("transport/link/tx/queue/size"))
    assert (sizes["interactive_high"], sizes["data"]) == (16, 16)  # directions are not dropped at 2 batches
    assert sizes["control"] == json.loads(
        zenoh.Config().get_json("transport/link/tx/queue/size/control")
    )  # Zenoh's own
    # open() returns as the port opens, not after a scouting delay with no subscriber (issue 34)
    assert json.loads(conf.get_json("scouting/delay")) == 0
    scouting = zenoh_config(load_config(None, {}, {"multicast": True}))
    assert scouting.get_json("scouting/delay") == "null"  # a planner that scouts keeps Zenoh's delay


def test_cli_config_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("lookahead = 1000\n")
    r = run_pfp("serve", "--config", str(bad))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == [f"pfp serve: {bad}: lookahead: must be between 0 and 100"]
    r = run_pfp("health", "--connect", "foo")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.strip() == (
        "pfp health: --connect: 'foo' is not an endpoint (expected PROTOCOL/ADDRESS, e.g. tcp/10.0.0.1:7447)"
    )
    env = {**os.environ, "PFP_UNIT_STALE_S": "-3"}
    r = subprocess.run(
        [sys.executable, "-m", "pfp_service", "serve"],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=60,
    )
    assert r.returncode == 2 and r.stderr.strip() == "pfp serve: PFP_UNIT_STALE_S: must be > 0"


def test_peer_planner_joins_an_existing_router_and_logs_json():
    """A router we own; the planner joins it with --connect; a unit on the router gets directions."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    mission = "j" + uuid.uuid4().hex[:8]
    with zenoh.open(conf):
        proc = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint,
             "--mission", mission, "--log-format", "json"],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        try:
            wait_for_planner(endpoint, mission)
            with client(endpoint) as s:
                u = Unit(s, mission, "scout-1")
                u.report()
                put_json(s, f"mumt/{mission}/unit/scout-1/goal", {"position": [50, 0]})
                d = u.inbox.get(where=lambda m: m["status"] == "en_route")
                assert d["vector"] == pytest.approx([1.0, 0.0])
        finally:
            proc.terminate()
            _out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0
    lines = [json.loads(line) for line in err.splitlines() if line.startswith("{")]
    assert any(r["msg"] == "goal set" and r["unit"] == "scout-1" for r in lines)
    assert time.time() - lines[-1]["ts"] < 60


def test_zenoh_json5_file_is_passed_through(tmp_path):
    port = free_port()
    j5 = tmp_path / "zenoh.json5"
    j5.write_text(
        "{\n  // a comment, as JSON5 allows\n  mode: 'peer',\n"
        f"  listen: {{ endpoints: ['tcp/127.0.0.1:{port}'] }},\n"
        "  transport: { link: { tx: { lease: 3000 } } },\n}\n"
    )
    conf = zenoh_config(load_config(None, {}, {"zenoh_config": str(j5), "mode": "client"}))
    assert json.loads(conf.get_json("transport/link/tx/lease")) == 3000  # from the file
    assert (
        json.loads(conf.get_json("transport/link/tx/queue/size/data")) == 2
    )  # the file's (Zenoh's), not ours
    assert f"tcp/127.0.0.1:{port}" in json.dumps(json.loads(conf.get_json("listen/endpoints")))
    assert json.loads(conf.get_json("mode")) == "client"  # our flag wins over the file
    with pytest.raises(InputError, match=r"^zenoh_config: .*missing.json5: no such file or directory$"):
        zenoh_config(load_config(None, {}, {"zenoh_config": str(tmp_path / "missing.json5")}))
