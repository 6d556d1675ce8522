"""The planner's options as a user names them, importable without the compiled core.

``pfp --help``, the scenario, config and goal validators and every refusal of a hostile
file need these names and defaults, but not numba, numpy or scipy: importing the core's
kernels costs about 100 MB of a command's peak memory (issue 35: a refusal stays within
200 MB).  So the names live here, and the modules that implement them import this one:
``escape_strategies`` registers one ``Strategy`` per name in ``ESCAPE_STRATEGIES``, and
``escape``, which runs them, checks at import that the two agree, name for name and in order.
"""

from __future__ import annotations

from typing import Literal

__all__ = ["DEFAULT_CELLS", "ESCAPES", "ESCAPE_STRATEGIES", "LAMBDA", "Intensity"]

ESCAPE_STRATEGIES: tuple[str, ...] = ("delta", "random", "waypoint", "contour", "global")
"""Every trap-escape strategy's name, in ``auto``'s order (by tier, then as registered)."""

ESCAPES: tuple[str, ...] = ("none", "auto", *ESCAPE_STRATEGIES)
"""The ``escape`` choices: no escape, ``auto``'s escalation, or one strategy alone."""

Intensity = Literal["peak", "density"]

LAMBDA = 10.0
"""Exposure weight of ``J = length + LAMBDA * exposure`` (metres per unit exposure)."""

DEFAULT_CELLS = 300
"""The optimal planner's grid: cells along the longer side of its search box."""
