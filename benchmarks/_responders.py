"""The responders ``pfp bench service`` measures against, each run as its own process.

``router_main`` is a plain Zenoh router (a cluster's, for ``--planners``);
``echo_main`` is a trivial Python zenoh responder that answers every unit
state with a fixed direction: the transport's own ceiling, the same-run
comparison for the planner's figures.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any

from benchmarks._load import MISSION, PLANNER_ID


def _router_until_signal(endpoint: str) -> tuple[threading.Event, Any]:
    """A router's Zenoh config on ``endpoint`` (multicast off), and an event SIGTERM or SIGINT sets."""
    import signal

    import zenoh

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return stop, conf


def router_main(endpoint: str) -> None:
    """A plain Zenoh router on ``endpoint`` until SIGTERM: the hub of a cluster's planners and the load."""
    import zenoh

    stop, conf = _router_until_signal(endpoint)
    with zenoh.open(conf):
        stop.wait()


def echo_main(endpoint: str) -> None:
    """The echo responder: a router that answers each unit state with a fixed direction.

    It decodes the state and parses its key exactly as the planner does and
    publishes with the planner's QoS, but plans nothing, so its latency and
    throughput are the transport's own on this machine.  It answers from the
    callback (no hand-off to another thread): the least any responder can do.
    """

    import zenoh

    from pfp_service.wire import Direction, DirectionStatus, PlannerStatus, decode_unit_state, encode, keys

    stop, conf = _router_until_signal(endpoint)
    counters = {"in": 0, "out": 0}
    started = time.monotonic()
    jenc = zenoh.Encoding.APPLICATION_JSON

    with zenoh.open(conf) as session:

        def on_state(sample: zenoh.Sample) -> None:
            try:
                uid = keys.parse(str(sample.key_expr)).id
                msg = decode_unit_state(sample.payload.to_bytes(), None)
            except Exception:
                return
            counters["in"] += 1
            d = Direction(unit=uid, seq=msg.seq, status=DirectionStatus.EN_ROUTE, vector=(1.0, 0.0))
            session.put(  # the planner's QoS for directions (node/node.py)
                keys.unit_direction(MISSION, uid),
                encode(d),
                encoding=jenc,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.INTERACTIVE_HIGH,
            )
            counters["out"] += 1

        def on_status(query: zenoh.Query) -> None:
            st = PlannerStatus(
                planner="echo",
                mission=MISSION,
                uptime_s=time.monotonic() - started,
                msgs_in=counters["in"],
                msgs_out=counters["out"],
            )
            query.reply(keys.planner_status(MISSION, PLANNER_ID), encode(st), encoding=jenc)

        sub = session.declare_subscriber(keys.unit_states_any(MISSION), on_state)
        qbl = session.declare_queryable(keys.planner_status(MISSION, PLANNER_ID), on_status)
        try:
            stop.wait()
        finally:
            qbl.undeclare()
            sub.undeclare()


# -- the load generator -----------------------------------------------------------------------
