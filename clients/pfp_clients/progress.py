"""Progress for long-running clients: a live bar on a terminal, a plain line every few seconds otherwise.

``Progress`` takes log lines (``say``) and a summary (``update``).  On a
terminal, rich draws the summary as a bar under the log lines; in a pipe or
a log file, the summary is printed as one more line at most every
``every_s`` wall seconds, and once more at the end, so a CI log stays short.
The clock is a parameter, so tests can drive it.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from types import TracebackType
from typing import IO, Any

__all__ = ["Progress"]


class Progress:
    """Log lines plus a summary that refreshes in place (terminal) or every ``every_s`` (pipe)."""

    def __init__(
        self,
        every_s: float = 5.0,
        stream: IO[str] | None = None,
        total: int | None = None,
        clock: Callable[[], float] = time.monotonic,
        live: bool | None = None,
    ) -> None:
        self.stream = stream if stream is not None else sys.stdout
        self.every_s = every_s
        self.total = total
        self.clock = clock
        self.live = self.stream.isatty() if live is None else live
        self._last_line_s = -float("inf")
        self._summary = ""
        self._printed = ""
        self._bar: Any = None
        self._task: Any = None

    def __enter__(self) -> Progress:
        if self.live:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn
            from rich.progress import Progress as Bar

            self._bar = Bar(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                console=Console(file=self.stream),
                transient=False,
            )
            self._bar.start()
            self._task = self._bar.add_task("starting", total=self.total)
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
        elif self._summary and self._summary != self._printed:
            self._print(self._summary)

    def say(self, line: str) -> None:
        """A log line: printed at once, above the bar if there is one."""
        if self._bar is not None:
            self._bar.console.print(line, markup=False, highlight=False)
        else:
            self._print(line)

    def update(self, summary: str, completed: int | None = None) -> None:
        """The current summary; ``completed`` of ``total`` fills the bar."""
        self._summary = summary
        if self._bar is not None:
            self._bar.update(self._task, description=summary, completed=completed or 0)
            return
        now = self.clock()
        if now - self._last_line_s >= self.every_s:
            self._last_line_s = now
            self._print(summary)

    def _print(self, line: str) -> None:
        self._printed = line
        print(line, file=self.stream, flush=True)
