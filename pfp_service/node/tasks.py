"""What a worker pool runs (``workers.WorkerPool``): a ``Task``, how it ended (``Outcome``), and the
threats it runs under, pickled once per field (``FieldBlob``, made by ``Blobs``) and shipped to a
worker only when it lacks that version.  Plain values, shared by the pool and its users (previews,
deliberation), apart from the pool's processes and threads.
"""

from __future__ import annotations

import math
import pickle
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

__all__ = ["Blobs", "FieldBlob", "Outcome", "OutcomeKind", "Task"]

OutcomeKind = Literal["done", "error", "memory", "killed", "died", "late", "closed"]


@dataclass(frozen=True, slots=True)
class FieldBlob:
    """The threats in force, pickled once: ``version`` names them in the workers' cache."""

    version: int
    data: bytes


class Blobs:
    """The parent's side of the field cache: one blob per threats tuple (by identity), the latest kept."""

    def __init__(self) -> None:
        self._threats: Any = None
        self._blob: FieldBlob | None = None
        self._version = 0

    def of(self, threats: tuple[Any, ...]) -> FieldBlob:
        if self._blob is None or self._threats is not threats:
            self._version += 1
            self._threats = threats
            self._blob = FieldBlob(self._version, pickle.dumps(threats, protocol=pickle.HIGHEST_PROTOCOL))
        return self._blob


@dataclass(frozen=True, slots=True)
class Outcome:
    """How a task ended: ``done`` with its ``value``, or why not (``detail``); ``run_s`` in the worker."""

    kind: OutcomeKind
    value: Any = None
    detail: str = ""
    run_s: float = 0.0


@dataclass(eq=False)
class Task:
    """One call of ``fn(*args)`` in a worker.

    Args:
        fn: a module-level function (it is pickled by name).
        done: called once with the ``Outcome``, from a pool thread.
        budget_s: run time allowed once started; the worker is killed ``KILL_GRACE_S`` past it.
        start_by: on ``time.monotonic``; not started by then, it is answered ``late`` unrun.
        field: the threats the task runs under (``world_threats`` in the worker).
        lane, priority: lower first.
        skip: asked before it starts; true drops it unanswered (it was superseded).
    """

    fn: Callable[..., Any]
    args: tuple[Any, ...]
    done: Callable[[Outcome], None]
    budget_s: float
    start_by: float = math.inf
    field: FieldBlob | None = None
    lane: int = 0
    priority: float = 0.0
    skip: Callable[[], bool] | None = None
    answered: bool = False  # set once ``done`` was called (``_finish``)
