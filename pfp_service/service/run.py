"""The planner's session lifecycle: open the Zenoh session, run a ``PlannerNode`` until told to stop, close.

``serve(cfg)`` is what ``pfp serve`` runs, and what a program embedding the
planner can run on its own thread (pass ``ready`` and ``stop``).  Zenoh's
errors (a port in use, no router to join) are translated here, at the edge,
into one ``ZenohError`` line.
"""

from __future__ import annotations

import signal
import threading

from pfp_service.errors import map_zenoh_errors
from pfp_service.service.config import DEFAULT_LISTEN, ServeConfig, zenoh_config
from pfp_service.service.log import setup_logging

__all__ = ["serve"]


def serve(cfg: ServeConfig, ready: threading.Event | None = None, stop: threading.Event | None = None) -> int:
    """Open the session, run the node until SIGTERM/SIGINT (or ``stop``), close everything.

    Args:
        cfg: the merged configuration.
        ready: set once the node is serving.
        stop: set it to stop; on the main thread SIGTERM and SIGINT set it too.

    Returns:
        0 after a clean stop.

    Raises:
        ZenohError: the session could not be opened (``--listen`` in use, ``--connect`` unreachable ...).
    """
    import zenoh

    from pfp_service.service.node import PlannerNode

    log = setup_logging(cfg.log_format, cfg.log_level)
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: stop.set())
    conf = zenoh_config(cfg)
    with map_zenoh_errors("--connect" if cfg.mode == "client" else "--listen"):
        session = zenoh.open(conf)
    with session:
        node = PlannerNode(session, cfg)
        node.start()
        try:
            endpoints = cfg.listen
            if endpoints is None:
                endpoints = [DEFAULT_LISTEN] if cfg.mode == "router" and cfg.zenoh_config is None else []
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
        finally:
            node.stop()
    log.info("stopped")
    return 0
