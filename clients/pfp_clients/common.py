"""What every client shares: opening its Zenoh session, and YAML files decoded with line numbers.

``load_yaml(path, Struct)`` turns a bad file into one ``InputError`` that names
the file, the line and the field (``team.yaml line 7, units[2].speed_mps: must
be > 0``), so a CLI prints one line and exits 2.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import msgspec
import yaml

from pfp_service import yamlio
from pfp_service.errors import InputError, Unreachable, from_validation, map_zenoh_errors
from pfp_service.files import read_text
from pfp_service.geo import localise_document
from pfp_service.service.config import DEFAULT_CONNECT, client_zenoh_config

__all__ = [
    "DEFAULT_CONNECT",
    "client_config",
    "line_of",
    "load_yaml",
    "located",
    "open_session",
    "open_session_waiting",
]

T = TypeVar("T")


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


_SEGMENT = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def line_of(root: yaml.Node | None, path: str) -> int | None:
    """The 1-based line of the YAML node at ``path`` (``timeline[3].position``), or its nearest parent."""
    node = root
    line = None if node is None else node.start_mark.line + 1
    for name, index in _SEGMENT.findall(path):
        nxt = None
        if index and isinstance(node, yaml.SequenceNode) and int(index) < len(node.value):
            nxt = node.value[int(index)]
        elif name and isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                if getattr(k, "value", None) == name:
                    nxt = v if not isinstance(v, yaml.ScalarNode) else k
                    break
        if nxt is None:
            break
        node = nxt
        line = node.start_mark.line + 1
    return line


def load_yaml(
    path: str | Path, cls: type[T], choices: dict[str, tuple[str, ...]] | None = None
) -> tuple[T, yaml.Node | None]:
    """Read and validate a YAML file as ``cls``; returns the value and the node tree (for line numbers).

    Raises:
        InputError: unreadable file, invalid YAML or an invalid field, with its line.
    """
    p = Path(path)
    text = read_text(p)
    try:
        root = yamlio.compose(text)
        obj = yamlio.load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{p.name} line {mark.line + 1}" if mark is not None else p.name
        raise InputError(where, f"invalid YAML: {getattr(exc, 'problem', None) or exc}") from None
    if not isinstance(obj, dict):
        raise InputError(p.name, f"expected a mapping at the top, got {type(obj).__name__}")
    try:
        obj = localise_document(obj)  # {lat, lon} positions to metres from the file's origin
    except InputError as bad:
        raise located(p, root, bad) from None
    try:
        return msgspec.convert(obj, cls), root
    except msgspec.ValidationError as exc:
        err = from_validation(exc, choices)
        name = err.path.rsplit(".", 1)[-1]
        if err.reason.startswith("invalid value") and name in (choices or {}):
            err = InputError(err.path, f"{err.reason} (expected one of: {', '.join((choices or {})[name])})")
        raise located(p, root, err) from None


def located(path: Path, root: yaml.Node | None, err: InputError) -> InputError:
    """``err`` with the file name and the line of its field prefixed to the path."""
    line = line_of(root, err.path)
    where = f"{path.name} line {line}" if line is not None else path.name
    return InputError(f"{where}, {err.path}" if err.path else where, err.reason)
