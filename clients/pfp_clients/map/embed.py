"""The map inside another program (``pfp demo --map``): its own thread, event loop and Zenoh session.

    with MapThread(client_config([endpoint]), MapOptions(mission=m, port=0)) as url:
        print(f"map: {url}")
        ...                      # the program runs; the page stays live
    # closed: the page's server, its subscriptions and its session

The map stays a client of the mission exactly as ``pfp map`` is: it opens its
own client session and sees only what goes over Zenoh.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from types import TracebackType
from typing import Any

from pfp_clients.map.server import MapOptions, serve

__all__ = ["MapThread"]


class MapThread:
    """Serve the map on a thread until ``close()`` (or the end of a ``with`` block).

    Args:
        conf: a ``zenoh.Config`` for the map's own session (client mode, as ``pfp map`` opens).
        opts: see ``MapOptions``; port 0 picks a free port.
        ready_timeout_s: how long ``start()`` waits for the page to be served.
    """

    def __init__(self, conf: Any, opts: MapOptions, ready_timeout_s: float = 20.0) -> None:
        self.conf = conf
        self.opts = opts
        self.ready_timeout_s = ready_timeout_s
        self.url: str | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._run, name="pfp-map", daemon=True)

    def _run(self) -> None:
        import zenoh

        try:
            with zenoh.open(self.conf) as session:
                asyncio.run(self._serve(session))
        except BaseException as exc:  # handed to start(): the caller's thread raises it
            self._error = exc
            self._ready.set()

    async def _serve(self, session: Any) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()

        def ready(url: str) -> None:
            self.url = url
            self._ready.set()

        await serve(session, self.opts, self._stop, say=lambda _line: None, ready=ready)

    def start(self) -> str:
        """Start serving and return the page's URL.

        Raises:
            TimeoutError: the page was not served within ``ready_timeout_s``.
            Exception: whatever stopped the map from starting (an unreachable router, a port in use).
        """
        self._thread.start()
        if not self._ready.wait(self.ready_timeout_s):
            self.close()
            raise TimeoutError(f"pfp map did not start within {self.ready_timeout_s:g} s")
        if self._error is not None:
            raise self._error
        assert self.url is not None
        return self.url

    def close(self) -> None:
        """Stop serving, undeclare, close the session, and wait for the thread."""
        if self._loop is not None and self._stop is not None:
            with contextlib.suppress(RuntimeError):  # the loop has already ended
                self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread.is_alive():
            self._thread.join(timeout=10)

    def __enter__(self) -> str:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
