"""The planner's session lifecycle: open the Zenoh session, run a ``PlannerNode`` until told to stop, close.

``serve(cfg)`` is what ``pfp serve`` runs, and what a program embedding the
planner can run on its own thread (pass ``ready`` and ``stop``).  Zenoh's
errors (a port in use, no router to join) are translated here, at the edge,
into one ``ZenohError`` line.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from typing import Any

from pfp_service.errors import map_zenoh_errors
from pfp_service.node.config import DEFAULT_LISTEN, ServeConfig, zenoh_config
from pfp_service.node.log import setup_logging
from pfp_service.signals import SignalStop

__all__ = ["serve"]

WAITING_LOG_S = 5.0  # while a client-mode planner waits for its router, one line this often


def serve(cfg: ServeConfig, ready: threading.Event | None = None, stop: threading.Event | None = None) -> int:
    """Open the session, run the node until SIGTERM/SIGINT (or ``stop``), close everything.

    Args:
        cfg: the merged configuration.
        ready: set once the node is serving.
        stop: set it to stop; on the main thread SIGTERM and SIGINT set it too.

    Returns:
        0 after a clean stop or SIGTERM, 130 after SIGINT (``pfp_service.signals``).

    Raises:
        ZenohError: the session could not be opened (``--listen`` in use, ``--connect`` unreachable ...).
    """
    from pfp_service.coords import Coords

    log = setup_logging(cfg.log_format, cfg.log_level, Coords.choose(cfg.coords, cfg.origin, strict=False))
    signals = SignalStop(stop)  # on the main thread, SIGTERM and SIGINT set stop too
    stop = signals.event
    with signals:
        return signals.exit_code(_serve(cfg, ready, stop, log))


def _serve(cfg: ServeConfig, ready: threading.Event | None, stop: threading.Event, log: Any) -> int:
    import zenoh

    # the configuration first: a bad --zenoh-config is refused before the planner's code is imported
    conf = zenoh_config(cfg)
    if cfg.mode == "client":  # a router that is down (or restarting) is waited for, not an exit
        conf.insert_json5("connect/timeout_ms", "-1")
        conf.insert_json5("connect/exit_on_failure", "false")

    from pfp_service.node.node import PlannerNode  # noqa: F401 -- imported before the router listens: the
    from pfp_service.node.previews import preview_service
    from pfp_service.node.store import Store  # node subscribes the moment the session opens (issue 34)

    fork_server: Any = contextlib.nullcontext()
    if threading.current_thread() is threading.main_thread():
        _few_arenas()
        fork_server = _fork_server(cfg)
    with fork_server:
        store = None if cfg.state_dir in ("none", "auto") else Store(cfg.state_dir)
        with contextlib.closing(store) if store is not None else contextlib.nullcontext():
            # the preview workers boot while the session opens: a client-mode planner waiting for its
            # router is ready to answer the moment the router comes, not seconds later
            previews = preview_service(cfg)
            try:
                session = _open(zenoh, conf, cfg, stop, log)
            except BaseException:
                previews.shutdown()
                raise
            if session is None:  # stopped while waiting for the router
                previews.shutdown()
                log.info("stopped")
                return 0
            with session:
                stopping = _run(session, cfg, store, previews, ready, stop, log)
    # the whole stop: the node's steps (``shutdown.run_steps`` names a slow one), the session, the store,
    # the fork server; a container's stop grace is about 10 s
    log.info("stopped", extra={"fields": {"stop_s": round(time.monotonic() - stopping, 2)}})
    return 0


def _open(zenoh: Any, conf: Any, cfg: ServeConfig, stop: threading.Event, log: Any) -> Any:
    """Open the session on a thread, logging while a client waits for its router; ``None`` if stopped."""
    box: dict[str, Any] = {}

    def opener() -> None:
        try:
            with map_zenoh_errors("--connect" if cfg.mode == "client" else "--listen"):
                box["session"] = zenoh.open(conf)
        except BaseException as exc:  # handed to the caller's thread
            box["error"] = exc

    t = threading.Thread(target=opener, name="pfp-open", daemon=True)
    t.start()
    t.join(2.0)
    next_log = 0.0
    warmed = False
    while t.is_alive():  # joined in short slices: the session is used the moment it opens
        if time.monotonic() >= next_log:
            log.warning("waiting for the router", extra={"fields": {"connect": cfg.connect}})
            next_log = time.monotonic() + WAITING_LOG_S
        if not warmed:  # the kernels load while the router is away, not once it has come
            from pfp_service.node.previews import warm_once

            warm_once(cfg.world_settings())
            warmed = True
        if stop.is_set():
            return None
        t.join(0.05)
    if "error" in box:
        raise box["error"]
    if warmed:
        log.info("router reached", extra={"fields": {"connect": cfg.connect}})
    return box["session"]


def _run(
    session: Any,
    cfg: ServeConfig,
    store: Any,
    previews: Any,
    ready: threading.Event | None,
    stop: threading.Event,
    log: Any,
) -> float:
    """Serve until ``stop``; returns the monotonic time the stop began."""
    from pfp_service.node.node import PlannerNode

    node = PlannerNode(session, cfg, store=store, previews=previews)
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
        stopping = time.monotonic()
        node.stop()
    return stopping


# A full collection waits for this many middle ones (CPython's default: 10).  It walks every
# object the world holds (about 10 a unit), so with a large fleet each one stalls the loop while
# the unit rings fill and pin their receive buffers, and none found any garbage (figures:
# docs/operations.md, "Figures behind the code's choices").  Young collections still run as
# ever, and a full one comes every few minutes under load.
FULL_COLLECTION_EVERY = 1000

M_ARENA_MAX = -8  # glibc's mallopt parameter
ARENAS = 2


@contextlib.contextmanager
def _fork_server(cfg: ServeConfig) -> Iterator[None]:
    """Warm this process, then fork the fork server its worker pools fork their workers from (``ForkServer``).

    Before the session opens and before any thread starts, so the fork is safe; the kernels are
    loaded first (for the defaults and for ``cfg``'s settings), so every worker is warm the moment
    it is forked, and ``gc.freeze`` keeps the collector from copying the shared pages.  Measured
    in one run (load 6-10): an idle planner's tree, summed PSS, fell from 214 MB in 2 processes
    (planner, one preview worker) to 130 MB in 3 (planner, fork server, that worker), and a worker
    starts in milliseconds, not seconds.
    """
    import gc

    from pfp_service.node.forkserver import ForkServer, install_fork_server
    from pfp_service.node.previews import WORKERS_WARM_TERRAIN, warm_up

    settings = cfg.world_settings()
    WORKERS_WARM_TERRAIN[0] = settings.terrain is not None
    warm_up(None, terrain=settings.terrain is not None)  # the workers forked from here plan as it does
    warm_up(settings)
    gc.collect()
    gc.freeze()
    young, middle, _ = gc.get_threshold()
    gc.set_threshold(young, middle, FULL_COLLECTION_EVERY)
    server = ForkServer.start()
    install_fork_server(server)
    try:
        yield
    finally:
        install_fork_server(None)
        if server is not None:
            server.close()


def _few_arenas() -> None:
    """At most ``ARENAS`` glibc malloc arenas, before the session's threads start.

    Each of Zenoh's and the planner's threads would otherwise get an arena of
    its own (up to 8 per core), each keeping what it freed: measured, the
    planner at 10,000 states/s peaked at 352 MB with 2 arenas against 394 MB
    with glibc's default, in the same run.  As ``MALLOC_ARENA_MAX=2``; a
    ``MALLOC_ARENA_MAX`` already set wins.  Nothing elsewhere than glibc.
    """
    import ctypes
    import os

    if "MALLOC_ARENA_MAX" in os.environ:
        return
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).mallopt(M_ARENA_MAX, ARENAS)
