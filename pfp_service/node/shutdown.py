"""A planner's stop, a step at a time: each step timed, and one warning naming the steps that were slow.

A container's stop grace is about 10 s (``docker stop``'s default), after
which the planner is killed and whatever it had not stored is lost.  A stop
takes 0.1-0.3 s; one that takes longer says which of its steps took the time,
so the next slow stop is explained by its own log rather than guessed at.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence

__all__ = ["SLOW_S", "join_within", "run_steps"]

SLOW_S = 1.0  # a step that takes this long or longer is named in the warning


def join_within(thread: threading.Thread | None, timeout_s: float) -> None:
    """Wait up to ``timeout_s`` for ``thread`` to end (``None``: nothing to wait for)."""
    if thread is not None:
        thread.join(timeout=timeout_s)


def run_steps(
    steps: Sequence[tuple[str, Callable[[], object]]],
    log: logging.Logger,
    clock: Callable[[], float] = time.monotonic,
) -> dict[str, float]:
    """Run ``steps`` in order (a step that raises stops the rest, as a plain sequence would); returns each
    step's seconds, and logs one warning with the slow ones (``SLOW_S``), if any."""
    took: dict[str, float] = {}
    try:
        for name, step in steps:
            t0 = clock()
            try:
                step()
            finally:
                took[name] = clock() - t0
    finally:
        slow = {name: round(s, 2) for name, s in took.items() if s >= SLOW_S}
        if slow:
            log.warning(
                "slow stop", extra={"fields": {"steps_s": slow, "total_s": round(sum(took.values()), 2)}}
            )
    return took
