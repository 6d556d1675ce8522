"""Which ``Host`` and ``Origin`` headers the map server answers (server.py's docstring says why).

A DNS-rebinding page names its own host, so a request must name one this
server serves; a browser's WebSocket names the page it came from, which must
be this server's own.
"""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Iterable

__all__ = ["host_allowed", "origin_allowed"]

_LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
_WILDCARDS = ("", "0.0.0.0", "::")


def _host_name(header: str) -> str:
    """The name in a ``Host`` header (``name``, ``name:port``, ``[v6]:port``), lower-case, no final dot."""
    text = header.strip().lower()
    if text.startswith("["):
        name = text[1 : text.find("]")] if "]" in text else ""
    else:
        name = text.rsplit(":", 1)[0] if text.count(":") == 1 else text
    return name.rstrip(".")


def _ip(name: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        return ipaddress.ip_address(name)
    except ValueError:
        return None


def origin_allowed(origin: str | None, host: str | None) -> bool:
    """Whether a WebSocket's ``Origin`` is this server's own: none (no browser), or ``http(s)://{Host}``."""
    if origin is None:
        return True
    scheme, sep, rest = origin.strip().partition("://")
    if not sep or scheme.lower() not in ("http", "https") or host is None:
        return False  # "null" (a sandboxed frame, a file:// page) or garbage: no origin of ours
    return _host_port(rest) == _host_port(host)


def _host_port(netloc: str) -> str:
    return netloc.strip().lower().rstrip("/").replace(".:", ":").rstrip(".")


def host_allowed(header: str | None, bind_host: str, extra: Iterable[str] = ()) -> bool:
    """Whether a request's ``Host`` header names a host this server serves.

    Allowed: the address it is bound to; for a loopback bind also ``localhost``,
    ``127.0.0.1`` and ``::1``; for a wildcard bind (``0.0.0.0``, ``::``) any IP
    address and this machine's name (an address is no DNS name, so it cannot be
    rebound); and every name in ``extra`` (``--allowed-host``).  A missing
    header is refused.
    """
    if not header:
        return False
    name = _host_name(header)
    if not name:
        return False
    bind = bind_host.strip("[]").lower()
    allowed = {bind, *(_host_name(h) for h in extra)}
    bind_ip = _ip(bind)
    if bind == "localhost" or (bind_ip is not None and bind_ip.is_loopback):
        allowed.update(_LOOPBACK_NAMES)
    if bind in _WILDCARDS:
        if _ip(name) is not None:
            return True
        allowed.update((*_LOOPBACK_NAMES, socket.gethostname().lower()))
    return name in allowed
