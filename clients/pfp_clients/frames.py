"""A client's origin against the planner's: learnt from its status, then the same, converted, or refused.

Team and script files may carry an ``origin`` (their ``[0, 0]``) and write
positions in metres from it.  The planner measures from its own ``--origin``.
Metres from two different points never mix: a client with an origin learns
the planner's from its status before it sends anything, and then

* the same origin: nothing changes;
* another origin: every position is converted exactly into the planner's
  frame, through lat/lon (``Reframe``), and the client says so in one line;
* a planner without an origin: refused, one line naming both (``InputError``).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import decode_planner_status, keys

__all__ = [
    "Reframe",
    "check_origin",
    "judge_origin",
    "learn_planner_origin",
    "planner_origin",
    "reframe",
    "shown",
]

Point = tuple[float, float]


def shown(o: Origin) -> str:
    """``50.01,8`` (and ``,ALT`` when the altitude is not 0): as ``--origin`` takes it."""
    return f"{o.lat:g},{o.lon:g}" + (f",{o.alt:g}" if o.alt else "")


@dataclass(frozen=True)
class Reframe:
    """Metres from ``mine`` to metres from ``theirs``: the same points on the earth."""

    mine: Origin
    theirs: Origin

    def __call__(self, p: Point) -> Point:
        return self.theirs.to_local(*self.mine.to_geodetic(p[0], p[1]))

    def line(self, what: str) -> str:
        return (
            f"the {what}'s origin {shown(self.mine)} differs from the planner's {shown(self.theirs)}: "
            "its positions are converted to the planner's frame"
        )


def reframe(mine: Origin | None, planner: Origin | None, mission: str, what: str) -> Reframe | None:
    """How to bring positions from ``mine`` into the planner's frame; ``None`` when nothing changes.

    Raises:
        InputError: at ``origin``, when ``mine`` is set and the planner has none (naming both).
    """
    if mine is None or planner == mine:
        return None
    if planner is None:
        raise InputError(
            "origin",
            f"the {what}'s origin is {shown(mine)} but the planner of mission {mission!r} has none: "
            f"start it with --origin {shown(mine)}, or leave origin out of the {what} file",
        )
    return Reframe(mine, planner)


def check_origin(
    session: Any, mission: str, mine: Origin, flag: str = "--origin", timeout_s: float = 1.0
) -> str | None:
    """A client that draws or converts with ``mine`` (the map, the TAK bridge) against the planner's own origin.

    Such a client has no file of its own metres: its origin only turns the planner's metres into lat/lon
    and back, so any origin but the planner's puts every position at the wrong place on the earth.

    Returns:
        ``None`` when a planner answered with the same origin; a line to log when none answered yet
        (nothing could be checked), or when the planner has none (its metres are taken from ``mine``).

    Raises:
        InputError: at ``flag``, when the planner's origin differs (naming both, and how far apart).
    """
    answered, planner = planner_origin(session, mission, timeout_s)
    if not answered:
        return f"no planner of mission {mission!r} answered yet: {flag} {shown(mine)} is not checked against its origin"
    return judge_origin(planner, mission, mine, flag)


def judge_origin(planner: Origin | None, mission: str, mine: Origin, flag: str = "--origin") -> str | None:
    """``check_origin``'s verdict once the planner has answered with its origin ``planner``.

    Returns:
        ``None`` when the two agree; a line to log when the planner has none.

    Raises:
        InputError: at ``flag``, when they differ.
    """
    if planner == mine:
        return None
    if planner is None:  # the planner works in plain metres: this client's origin says where they lie
        return f"the planner of mission {mission!r} has no origin: its metres are taken from {flag} {shown(mine)}"
    x, y = planner.to_local(mine.lat, mine.lon)
    raise InputError(
        flag,
        f"{shown(mine)} differs from the origin of the planner of mission {mission!r}, {shown(planner)} "
        f"({math.hypot(x, y):,.0f} m away): every position would be off by that much; use {flag} {shown(planner)}",
    )


def planner_origin(session: Any, mission: str, timeout_s: float = 1.0) -> tuple[bool, Origin | None]:
    """Whether a planner of ``mission`` answered its status, and its origin (``None``: plain metres)."""
    for reply in session.get(keys.planner_statuses(mission), timeout=timeout_s):
        if reply.ok is None:
            continue
        try:
            return True, decode_planner_status(reply.ok.payload.to_bytes()).origin
        except InputError:
            continue
    return False, None


def learn_planner_origin(
    session: Any,
    mission: str,
    stop: threading.Event,
    say: Callable[[str], None],
    what: str,
    why: str | None = None,
) -> tuple[bool, Origin | None]:
    """``planner_origin``, asked every second until a planner answers or ``stop``; says it waits, once.

    ``why`` is what the wait line gives as the reason (default: the ``what`` file's origin is checked).

    Returns:
        ``(False, None)`` if stopped before any planner answered.
    """
    told = False
    while not stop.is_set():
        answered, origin = planner_origin(session, mission)
        if answered:
            return True, origin
        if not told:
            reason = why or f"the {what}'s origin is checked against its own"
            say(f"waiting for a planner of mission {mission!r}: {reason}")
            told = True
        stop.wait(1.0)
    return False, None
