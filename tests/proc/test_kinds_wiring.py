"""The node's subscriptions come from the kinds' table: a real ``PlannerNode`` declares each kind's key as its mode says.

``world.kinds.KINDS`` names every key the planner takes input on and how the node reads it
(``Kind.mode``); ``node._wire`` declares each.  A kind left out of the wiring, or wired on
another key, fails here.  ``proc``: the node starts its worker processes.
"""

from __future__ import annotations

import collections
import json

import pytest
import zenoh

from pfp_service.node.config import ServeConfig
from pfp_service.node.node import PlannerNode
from pfp_service.world.kinds import KINDS
from tests.zenoh_util import free_port

pytestmark = pytest.mark.proc

M = "wired"
WANT = {"write": 2, "token": 1, "peers": 1, "state": 0}  # subscriber and queryable; the state's is a ring


def _router(endpoint: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


@pytest.mark.parametrize("cluster", [False, True], ids=["alone", "cluster"])
def test_a_planner_subscribes_to_every_kind_as_its_mode_says(cluster):
    session = _router(f"tcp/127.0.0.1:{free_port()}")
    cfg = ServeConfig(mission=M, planner_id="p1", cluster=cluster, preview_workers=1, deliberation_workers=1)
    node = PlannerNode(session, cfg)
    try:
        node._listen(session)
        declared = collections.Counter(str(d.key_expr) for d in node._declared)
        rings = {name: str(sub.key_expr) for name, (sub, _ring, _armed) in node._rings._rings.items()}
        for kind in KINDS:
            want = WANT.get(kind.mode, 1 if cluster else 0)  # what planners share: under --cluster only
            assert declared[kind.wildcard(M)] == want, (kind.name, kind.mode)
            if kind.mode == "state":
                assert rings["plain"] == kind.wildcard(M)
        others = {str(k) for k in declared} - {k.wildcard(M) for k in KINDS}
        assert others == {
            f"mumt/{M}/preview/*",
            f"mumt/{M}/preview/team/*",
            f"mumt/{M}/planner/p1/status",
            f"mumt/{M}/planner/p1/world",
        }
    finally:
        node.stop()
        session.close()
