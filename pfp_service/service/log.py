"""Structured logging: readable lines on a terminal, JSON lines when asked.

Every record may carry fields (``unit``, ``threat``, ``key`` ...) passed as
``extra={"fields": {...}}``; a line about a unit always names it.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from collections.abc import Iterable
from typing import Any

__all__ = ["get_logger", "setup_logging"]

_ROOT = "pfp"


class _Human(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        fields = getattr(record, "fields", {}) or {}
        stamp = time.strftime("%H:%M:%S", time.localtime(record.created)) + f".{int(record.msecs):03d}"
        extra = " ".join(f"{k}={v}" for k, v in fields.items())
        line = f"{stamp} {record.levelname:<7} {record.getMessage()}" + (f"  {extra}" if extra else "")
        if record.exc_info:
            line += "\n" + self.formatException(record.exc_info)
        return line


class _Json(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        doc: dict[str, Any] = {
            "ts": round(record.created, 6),
            "level": record.levelname.lower(),
            "logger": record.name,
            "msg": record.getMessage(),
        }
        doc.update(getattr(record, "fields", {}) or {})
        if record.exc_info:
            doc["exc"] = self.formatException(record.exc_info)
        return json.dumps(doc, default=str)


def setup_logging(fmt: str = "human", level: str = "info") -> logging.Logger:
    """Configure the ``pfp`` logger tree to write to stderr."""
    logger = logging.getLogger(_ROOT)
    logger.handlers.clear()
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Json() if fmt == "json" else _Human())
    logger.addHandler(handler)
    logger.setLevel(level.upper())
    logger.propagate = False
    return logger


def get_logger(name: str) -> logging.Logger:
    return logging.getLogger(f"{_ROOT}.{name}")


def log_changes(logger: logging.Logger, inputs: Iterable[object], limit: int = 20) -> None:
    """One line per goal or threat change among ``inputs``, at most ``limit`` and a count of the rest."""
    # here, not at the top: every process logs, and only the planner holds the world's inputs
    from pfp_service.service.events import GoalCancelled, GoalSet, ThreatPut, ThreatRemoved

    shown = 0
    for inp in inputs:
        if isinstance(inp, GoalSet):
            msg, fields = "goal set", {"unit": inp.unit, "goal": list(inp.goal.position)}
        elif isinstance(inp, GoalCancelled):
            msg, fields = "goal cancelled", {"unit": inp.unit}
        elif isinstance(inp, ThreatPut):
            msg, fields = "threat put", {"threat": inp.threat, "position": list(inp.update.position)}
        elif isinstance(inp, ThreatRemoved):
            msg, fields = "threat removed", {"threat": inp.threat}
        else:
            continue
        shown += 1
        if shown <= limit:
            logger.info(msg, extra={"fields": fields})
    if shown > limit:
        logger.info("more goal and threat changes", extra={"fields": {"count": shown - limit}})
