"""The cyclic garbage collector held off for one bounded stretch of work, and run once after it.

CPython's collector runs whenever 700 more containers were made than freed:
a contingency wave's ``World.apply`` (1,000 units) makes ~7,000 and so
stopped ~10 times for a young collection and once for an older one, 1-3 ms
of its ~10 (docs/operations.md, "The collector").  ``paused()`` disables the
collector for the stretch; the allocation counts keep growing, so the first
allocation after it collects at once, one collection over what the stretch
left alive (what died meanwhile is freed by reference counting as ever).  The
garbage held back is bounded by one stretch's allocations: nothing is ever
left uncollected, and nesting, or a collector already off, leaves it as it
was.  Not I/O: the world's parts may use it.
"""

from __future__ import annotations

import gc
from types import TracebackType

__all__ = ["paused"]


class paused:
    """``with paused():`` the collector is off inside and back on after (if it was on before)."""

    __slots__ = ("_was",)

    def __enter__(self) -> None:
        self._was = gc.isenabled()
        if self._was:
            gc.disable()

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._was:
            gc.enable()
