"""Structured logging: readable lines on a terminal, JSON lines when asked.

Every record may carry fields (``unit``, ``threat``, ``key`` ...) passed as
``extra={"fields": {...}}``; a line about a unit always names it.

The human lines are for people: values, not reprs, rounded to what matters
(``distance_to_goal=3.21``, not ``3.2099999999999866``), nested records as
their values (``changes=[e1 put at …]``, not ``[ThreatChange(threat='e1', …)]``),
and every position (a message argument wrapped in ``At``, a ``position`` or
``goal`` field) in the mission's coordinates: ``58.41050N 15.62130E (300 m E,
260 m N)`` with an origin (``pfp_service.coords``), metres without one.  JSON
lines keep the numbers as they are, metres, plus ``lat``/``lon`` where known.
"""

from __future__ import annotations

import json
import logging
import math
import sys
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from pfp_service.coords import Coords

__all__ = ["At", "get_logger", "human_value", "log_changes", "setup_logging"]

_ROOT = "pfp"
# field names whose value is a local [x, y] in metres
_POSITION_FIELDS = frozenset({"position", "goal", "start", "at", "of"})


@dataclass(frozen=True)
class At:
    """A local position as a log message argument: the human formatter shows it in the mission's coords."""

    x: float
    y: float

    def __str__(self) -> str:
        return f"({self.x:.1f}, {self.y:.1f})"


def _is_point(value: object) -> bool:
    return (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    )


def _number(value: float) -> str:
    if not math.isfinite(value):
        return str(value)
    if value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.4g}" if abs(value) < 1e4 else f"{value:.0f}"


def human_value(value: Any, coords: Coords, key: str = "") -> str:
    """One field's value for a person: numbers rounded, positions in ``coords``, records as their values.

    Args:
        value: the field's value (numbers, text, lists, mappings, msgspec Structs, dataclasses).
        coords: how positions are shown.
        key: the field's name; a ``position``-like name marks ``[x, y]`` as a position.
    """
    import msgspec

    if key in _POSITION_FIELDS and _is_point(value):
        return coords.point(value)
    if isinstance(value, At):
        return coords.point((value.x, value.y))
    if isinstance(value, bool) or value is None:
        return str(value).lower() if isinstance(value, bool) else "-"
    if isinstance(value, float):
        return _number(value)
    if isinstance(value, msgspec.Struct):
        value = {f: getattr(value, f) for f in value.__struct_fields__}
        if set(value) >= {"threat", "change"}:  # a ThreatChange: "e1 put at …"
            at = value.get("position")
            return f"{value['threat']} {value['change']}" + (
                f" at {human_value(at, coords, 'position')}" if at is not None else ""
            )
    if isinstance(value, Mapping):
        inner = (f"{k}={human_value(v, coords, str(k))}" for k, v in value.items() if v is not None)
        return "{" + " ".join(inner) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(human_value(v, coords) for v in value) + "]"
    return str(value)


class _JsonOnly(dict[str, object]):
    """Fields the human line already says in its message: JSON lines carry them, human lines do not."""


def _json_only(fields: dict[str, object]) -> _JsonOnly:
    return _JsonOnly(fields)


class _Human(logging.Formatter):
    def __init__(self, coords: Coords | None = None) -> None:
        super().__init__()
        self.coords = coords or Coords()

    def format(self, record: logging.LogRecord) -> str:
        fields = getattr(record, "fields", {}) or {}
        if isinstance(fields, _JsonOnly):
            fields = {}
        stamp = time.strftime("%H:%M:%S", time.localtime(record.created)) + f".{int(record.msecs):03d}"
        extra = " ".join(f"{k}={human_value(v, self.coords, k)}" for k, v in fields.items())
        msg = record.getMessage()
        if isinstance(record.args, tuple) and any(isinstance(a, At) for a in record.args):
            args = tuple(self.coords.point((a.x, a.y)) if isinstance(a, At) else a for a in record.args)
            msg = str(record.msg) % args
        line = f"{stamp} {record.levelname:<7} {msg}" + (f"  {extra}" if extra else "")
        if record.exc_info:
            line += "\n" + self.formatException(record.exc_info)
        return line


class _Json(logging.Formatter):
    def __init__(self, coords: Coords | None = None) -> None:
        super().__init__()
        self.coords = coords or Coords()

    def format(self, record: logging.LogRecord) -> str:
        doc: dict[str, Any] = {
            "ts": round(record.created, 6),
            "level": record.levelname.lower(),
            "logger": record.name,
            # a stable message for machines ("threat put"), where the human one carries values
            "msg": getattr(record, "json_msg", None) or record.getMessage(),
        }
        fields = getattr(record, "fields", {}) or {}
        doc.update(fields)
        pos = fields.get("position", fields.get("goal"))
        if pos is not None and _is_point(pos) and (ll := self.coords.latlon(pos)) is not None:
            doc.setdefault("lat", round(ll[0], 7))
            doc.setdefault("lon", round(ll[1], 7))
        if record.exc_info:
            doc["exc"] = self.formatException(record.exc_info)
        return json.dumps(doc, default=_builtin)


def _builtin(value: Any) -> Any:
    import msgspec

    if isinstance(value, At):
        return [value.x, value.y]
    try:
        return msgspec.to_builtins(value)
    except TypeError:
        return str(value)


def setup_logging(fmt: str = "human", level: str = "info", coords: Coords | None = None) -> logging.Logger:
    """Configure the ``pfp`` logger tree to write to stderr.

    Args:
        fmt: ``human`` or ``json``.
        level: the lowest level written.
        coords: how the human lines show positions (default: metres); JSON lines add lat/lon with an origin.
    """
    logger = logging.getLogger(_ROOT)
    logger.handlers.clear()
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Json(coords) if fmt == "json" else _Human(coords))
    logger.addHandler(handler)
    logger.setLevel(level.upper())
    logger.propagate = False
    return logger


def get_logger(name: str) -> logging.Logger:
    return logging.getLogger(f"{_ROOT}.{name}")


def log_changes(logger: logging.Logger, inputs: Iterable[object], limit: int = 20) -> None:
    """One line per write (a goal, threat or zone change) among ``inputs``, at most ``limit`` and a count of the rest.

    ``threat e1 put at 58.41050N 15.62130E (300 m E, 260 m N)``: the position is an ``At``,
    shown in the mission's coordinates by the human formatter.
    """
    # here, not at the top: every process logs, and only the planner holds the world's inputs
    from pfp_service.world.kinds import WRITES, log_line

    shown = 0
    for inp in inputs:
        line = log_line(inp)  # the write kinds' table says each change's line (world.kinds)
        if line is None:
            continue
        shown += 1
        if shown <= limit:
            args = line.args if line.at is None else (*line.args, At(*line.at))
            logger.info(line.msg, *args, extra={"fields": _json_only(line.fields), "json_msg": line.what})
    if shown > limit:
        names = [k.name for k in WRITES]
        said = ", ".join(names[:-1]) + f" and {names[-1]}" if len(names) > 1 else names[0]
        logger.info(f"more {said} changes", extra={"fields": {"count": shown - limit}})
