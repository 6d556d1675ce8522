"""``pfp acl`` writes the transmit queues ``pfp serve`` sets by default, in every config it writes.

One source (``config.TX_QUEUE_BATCHES``): the router's and each client's
``transport/link/tx/queue/size``, as Zenoh reads the written file, equals what
``zenoh_config`` gives ``pfp serve`` with no ``--zenoh-config``.
"""

from __future__ import annotations

import json

import pytest
import zenoh

from pfp_service.cli import main as pfp_main
from pfp_service.node.config import TX_QUEUE_BATCHES, ServeConfig, zenoh_config

pytestmark = pytest.mark.unit

QUEUE = "transport/link/tx/queue/size"


def test_every_config_pfp_acl_writes_has_the_serve_default_transmit_queues(tmp_path):
    team = tmp_path / "team.yaml"
    team.write_text("units:\n  - {id: u1, start: [0, 0], goal: [10, 10]}\n")
    out = tmp_path / "acl"
    assert pfp_main(["acl", str(team), "--out", str(out), "--tls", "--quiet"]) == 0
    serve = json.loads(zenoh_config(ServeConfig()).get_json(QUEUE))
    assert {k: serve[k] for k in TX_QUEUE_BATCHES} == TX_QUEUE_BATCHES  # the default is the deep queue
    files = [
        out / "zenoh-router.json5",
        out / "zenoh-router-mtls.json5",
        *sorted((out / "clients").iterdir()),
    ]
    assert len(files) > 4
    for path in files:
        written = json.loads(zenoh.Config.from_file(str(path)).get_json(QUEUE))
        assert written == serve, path.name
