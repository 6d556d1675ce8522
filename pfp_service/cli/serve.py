"""``pfp serve``: run the planner daemon on Zenoh (embedded router by default)."""

from __future__ import annotations

import argparse
import json
import os
import signal
import threading
from typing import Any

from pfp_service.cli._common import positive_float, positive_int
from pfp_service.core.params import ESCAPES


def _bounds(text: str) -> object:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        raise argparse.ArgumentTypeError("expected JSON like [[0, 0], [100, 100]]") from None


def _origin(text: str) -> object:
    import msgspec

    from pfp_service.errors import InputError
    from pfp_service.geo import parse_origin

    try:
        return msgspec.to_builtins(parse_origin(text))
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None


def register(sub: Any) -> None:
    p = sub.add_parser(
        "serve",
        help="run the planner daemon",
        description=__doc__ + " Precedence: defaults < --config TOML < PFP_* environment < flags.",
    )
    p.add_argument("--config", metavar="TOML", help="configuration file")
    p.add_argument("--zenoh-config", metavar="JSON5", help="Zenoh configuration file passed through")
    p.add_argument("--mode", choices=("router", "peer", "client"), help="Zenoh mode (default router)")
    p.add_argument("--listen", action="append", metavar="ENDPOINT", help="listen endpoint (repeatable)")
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router or peer to join (repeatable)"
    )
    p.add_argument("--mission", help="mission name (default: default)")
    p.add_argument("--planner-id", help="this planner's id (default: planner)")
    p.add_argument("--log-format", choices=("human", "json"))
    p.add_argument("--log-level", choices=("debug", "info", "warning", "error"))
    p.add_argument("--delta", type=positive_float)
    p.add_argument("--step", type=positive_float)
    p.add_argument("--tolerance", type=positive_float)
    p.add_argument("--intensity", choices=("peak", "density"))
    p.add_argument("--escape", choices=ESCAPES)
    p.add_argument("--threat-ttl-s", type=positive_float, help="default TTL of threats that carry none")
    p.add_argument("--unit-stale-s", type=positive_float, help="silence after which a unit is stale")
    p.add_argument("--liveliness-debounce-s", type=float, help="how long a token must stay gone")
    p.add_argument("--preview-budget-ms", type=positive_float, help="time budget of one preview")
    p.add_argument("--preview-max-iter", type=positive_int, help="iteration cap of one preview")
    p.add_argument("--lookahead", type=int, help="predicted positions per direction (0-100)")
    p.add_argument("--tick-s", type=positive_float, help="longest wait of the planning loop when idle")
    p.add_argument("--bounds", type=_bounds, metavar="JSON", help="mission bounds [[xmin,ymin],[xmax,ymax]]")
    p.add_argument("--multicast", action="store_const", const=True, help="enable Zenoh multicast scouting")
    p.add_argument(
        "--origin",
        type=_origin,
        metavar="LAT,LON[,ALT]",
        help="mission origin in WGS-84 degrees (and metres): [0, 0] lies there and positions may be "
        "{lat, lon} (default: none)",
    )
    p.set_defaults(func=run)


_FLAG_KEYS = [
    "mode",
    "listen",
    "connect",
    "mission",
    "planner_id",
    "log_format",
    "log_level",
    "delta",
    "step",
    "tolerance",
    "intensity",
    "escape",
    "threat_ttl_s",
    "unit_stale_s",
    "liveliness_debounce_s",
    "preview_budget_ms",
    "preview_max_iter",
    "lookahead",
    "tick_s",
    "bounds",
    "origin",
    "multicast",
    "zenoh_config",
]


def run(args: argparse.Namespace) -> int:
    from pfp_service.service.config import load_config

    flags = {k: getattr(args, k) for k in _FLAG_KEYS}
    cfg = load_config(args.config, os.environ, flags)
    return serve(cfg)


def serve(cfg: Any, ready: threading.Event | None = None, stop: threading.Event | None = None) -> int:
    """Open the session, run the node until SIGTERM/SIGINT (or ``stop``), close everything."""
    import zenoh

    from pfp_service.errors import InputError
    from pfp_service.service.config import zenoh_config
    from pfp_service.service.log import setup_logging
    from pfp_service.service.node import PlannerNode

    log = setup_logging(cfg.log_format, cfg.log_level)
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: stop.set())
    conf = zenoh_config(cfg)
    try:
        session = zenoh.open(conf)
    except Exception as exc:  # zenoh.ZError: endpoint in use, router unreachable ...
        raise InputError("zenoh", f"cannot open session: {exc}") from None
    try:
        node = PlannerNode(session, cfg)
        node.start()
        endpoints = (
            cfg.listen or ([] if cfg.zenoh_config else ["tcp/127.0.0.1:7447"])
            if cfg.mode == "router"
            else cfg.listen
        )
        log.info(
            "serving",
            extra={
                "fields": {
                    "mode": cfg.mode,
                    "listen": endpoints,
                    "connect": cfg.connect,
                    "mission": cfg.mission,
                }
            },
        )
        if ready is not None:
            ready.set()
        stop.wait()
        log.info("shutting down")
        node.stop()
    finally:
        session.close()
    log.info("stopped")
    return 0
