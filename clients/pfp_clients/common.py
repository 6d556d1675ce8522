"""What every client shares: opening its Zenoh session, at once or waiting for its router.

Files are read with ``pfp_service.yamlio.load_yaml``, which names the file,
the line and the field of what is wrong.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from pfp_service.errors import Unreachable, map_zenoh_errors
from pfp_service.node.config import DEFAULT_CONNECT, client_zenoh_config

__all__ = [
    "DEFAULT_CONNECT",
    "client_config",
    "open_session",
    "open_session_waiting",
]


def client_config(connect: Sequence[str] | None = None, multicast: bool = False) -> Any:
    """A ``zenoh.Config`` in client mode connecting to ``connect`` (default ``DEFAULT_CONNECT``)."""
    return client_zenoh_config(connect, multicast)


def open_session(conf: Any) -> Any:
    """``zenoh.open(conf)``, its errors as one line: use it as ``with open_session(conf) as session:``.

    Raises:
        Unreachable: ``--connect``, no router answers; ZenohError: anything else Zenoh refused.
    """
    import zenoh

    with map_zenoh_errors("--connect"):
        return zenoh.open(conf)


def open_session_waiting(
    conf: Any, say: Callable[[str], None], stop: threading.Event | None = None, note_s: float = 10.0
) -> Any:
    """``open_session(conf)``, but a router that is not up yet is waited for, saying so every ``note_s``.

    A client started before ``pfp serve`` (which is the router by default) then
    joins once it is up, retrying every 0.5 s at most, instead of exiting.

    Returns:
        The session, or ``None`` if ``stop`` was set while waiting.

    Raises:
        ZenohError: anything Zenoh refused other than an absent router.
    """
    import json

    import zenoh

    try:
        return open_session(conf)
    except Unreachable as exc:
        say(f"waiting for the router: {exc.reason}")
    conf.insert_json5("connect/timeout_ms", "-1")
    conf.insert_json5("connect/exit_on_failure", "false")
    retry = {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 1.5}
    conf.insert_json5("connect/retry", json.dumps(retry))
    box: dict[str, Any] = {}

    def opener() -> None:
        try:
            with map_zenoh_errors("--connect"):
                box["session"] = zenoh.open(conf)
        except BaseException as exc:  # handed to the caller's thread
            box["error"] = exc

    t = threading.Thread(target=opener, name="pfp-open", daemon=True)
    t.start()
    started = time.monotonic()
    while t.is_alive():
        t.join(0.1)
        if stop is not None and stop.is_set():
            return None
        if t.is_alive() and time.monotonic() - started >= note_s:
            started = time.monotonic()
            say("still waiting for the router")
    if "error" in box:
        raise box["error"]
    say("router reached")
    return box["session"]
