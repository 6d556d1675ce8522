"""The ground under the live world, as the world takes it: a line of sight for the threats and barriers.

``WorldSettings.terrain`` holds a ``Ground`` (``terrain.live.LiveTerrain``,
loaded by the node before the world starts): every threat's packed row is
masked by its window of lowest visible heights (``core.visibility``), and
its ``zones`` (ground too steep for the mission's unit class, and unknown
ground; a unit whose goal names another class, ``world.mobility``, plans
around its ``barriers`` for that class's slope instead) are in force with the keep-out zones put on the wire, so the
stepper, deliberation and previews treat them alike, as ``pfp plan
--terrain`` does; its ``sees`` is the line of sight a controller's link
keeps to its robots (``team_book``), from the controller's own height to the
robot's (``team_masts``); its ``over_ground`` measures a preview's path over
it (elevations, climb, steepest ground, and the ETA at the unit's own
mobility: ``world.preview``).  None changes while the planner runs.  The world never
reads the DEM: it is handed what it needs.

Sight off the loop.  A threat's window is a viewshed sweep over its reach
(tens of milliseconds over a 5 km reach on 10 m cells), too dear for the
planning loop.  A threat put over terrain whose window the world does not
hold yet is *held*: the world emits a ``SightAsk`` (``Outputs.sights``),
the node computes it off the loop (``node.terrain.Sights``, latest wins)
and hands it back as an ``events.SightLanded``, versioned by its ``key``
(position, eye and reach box): a window for a threat since moved or
removed is dropped.  Until it lands the world stands as before the put
(the threat's previous position and window, or none).  If it has not
landed ``WorldSettings.sight_wait_s`` after the put, the threat takes force
blind -- seeing everywhere, the conservative stand-in -- and the window, when
it lands, masks it then.  A world that deliberates inline (tests, the
warm-up) computes the window in ``apply``.  ``Looks`` is the world's
book of windows landed; the world's rows and ``reach.reached`` read it,
never the ground.

Slope barriers off the loop.  The barriers of a unit's own slope limit, when
it is not a class's (those are built when the terrain loads), are asked the
same way: a ``SlopeAsk`` (``Outputs.slopes``), built by the node's thread
(``answer_slope``: ``Ground.build_barriers``, 0.5-1.3 s) and landed as a
``SlopeLanded``; until then the unit plans at its class's safe side
(``world.slopes``).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:  # the compiled core's types: the world's inputs (``events``) import this module
    from pfp_service.core.mobility import Mobility
    from pfp_service.core.visibility import Sight as ThreatSight
    from pfp_service.core.visibility import Window
    from pfp_service.core.zones import Zone
    from pfp_service.world.teams import Sight

__all__ = [
    "LOOKS_SPARE",
    "Ground",
    "Looks",
    "SightAsk",
    "SightLanded",
    "SlopeAsk",
    "SlopeLanded",
    "answer",
    "answer_slope",
    "ground_zones",
    "link_sight",
    "sight_key",
    "sight_of",
]

LOOKS_SPARE = 64  # windows kept past two a threat: a threat put back where it stood finds its own
SightKey = tuple[float, ...]


class Ground(Protocol):
    """What the world takes from a terrain: a ``core.visibility.Sight`` and the barrier zones."""

    @property
    def zones(self) -> Sequence[Zone]: ...

    def __call__(self, threat: object, box: tuple[float, float, float, float]) -> Window | None: ...

    def barriers(self, max_slope_deg: int | None) -> Sequence[Zone]: ...

    def build_barriers(self, max_slope_deg: int) -> Sequence[Zone]: ...

    def sees(
        self,
        a: tuple[float, float],
        b: tuple[float, float],
        clearance_m: float = 0.0,
        masts: tuple[float | None, float | None] = (None, None),
    ) -> bool: ...

    @property
    def resolution_m(self) -> float: ...

    def over_ground(
        self, path: Sequence[tuple[float, float]], unit: Mobility | None
    ) -> dict[str, object]: ...


@dataclass(frozen=True, slots=True)
class SightAsk:
    """A threat's window to compute off the loop (``answer``): ``box`` is its reach (``visibility.reach_box``)."""

    threat: str
    key: SightKey
    target: Any  # the ``core.Threat``
    box: tuple[float, float, float, float]
    corridors: Any = None  # ``wave.Corridors``: the units its landing re-judges, judged with the window


@dataclass(frozen=True, slots=True)
class SightLanded:
    """An input: the window ``SightAsk`` asked for (``None``: the threat sees everywhere), under its key."""

    threat: str
    key: SightKey
    window: Window | None
    judged: Any = None  # ``wave.Judged``: which of the ask's corridors it reaches, judged off the loop


@dataclass(frozen=True, slots=True)
class SlopeAsk:
    """The barrier set of an override slope limit to build off the loop (``answer_slope``; ``world.slopes``),
    ``serial`` its version: a landing for an ask given up since is dropped."""

    limit: int
    serial: int


@dataclass(frozen=True, slots=True)
class SlopeLanded:
    """An input: the barrier set ``SlopeAsk`` asked for, or ``zones`` ``None`` and why it failed (``error``)."""

    limit: int
    serial: int
    zones: tuple[Zone, ...] | None
    error: str = ""


def answer_slope(ground: Ground, ask: SlopeAsk) -> SlopeLanded:
    """The barrier set ``ask`` wants, landed; a build that raises lands as its failure (call it off the loop)."""
    try:
        zones = tuple(ground.build_barriers(ask.limit))
    except Exception as exc:  # failure as a value: its units stay at the class limit (``world.slopes``)
        return SlopeLanded(ask.limit, ask.serial, None, f"{type(exc).__name__}: {str(exc)[:160]}")
    return SlopeLanded(ask.limit, ask.serial, zones)


def sight_key(threat: Any, box: tuple[float, float, float, float]) -> SightKey:
    """What a window depends on: the threat's position and eye, and the box of its reach."""
    return (float(threat.xi[0]), float(threat.xi[1]), float(threat.observer_height_m), *box)


def answer(ground: Ground, ask: SightAsk) -> SightLanded:
    """The window ``ask`` wants, landed (the sweep: call it off the loop)."""
    return SightLanded(ask.threat, ask.key, ground(ask.target, ask.box))


class Looks:
    """The windows landed, by ``sight_key``; a ``core.visibility.Sight`` that never computes one.

    Asked for a window not landed it answers ``None``: the threat sees
    everywhere (blind, the safe side).  At most two windows a threat in force
    and ``LOOKS_SPARE`` more are kept, the least recently used dropped.
    """

    def __init__(self) -> None:
        self._windows: OrderedDict[SightKey, Window | None] = OrderedDict()

    def __contains__(self, key: object) -> bool:
        return key in self._windows

    def __len__(self) -> int:
        return len(self._windows)

    def __call__(self, threat: Any, box: tuple[float, float, float, float]) -> Window | None:
        key = sight_key(threat, box)
        got = self._windows.get(key)
        if got is not None:
            self._windows.move_to_end(key)
        return got

    def land(self, key: SightKey, window: Window | None, threats: int) -> None:
        """Keep ``window`` under ``key``, with ``threats`` in force."""
        self._windows[key] = window
        self._windows.move_to_end(key)
        while len(self._windows) > 2 * threats + LOOKS_SPARE:
            self._windows.popitem(last=False)


def sight_of(ground: Ground | None, height_m: float | None = None) -> ThreatSight | None:
    """The sight a field of the world's threats is built with off the loop, or ``None``: the ground itself,
    or its windows for a unit ``height_m`` tall (``core.visibility.AtHeight``: no sweep again)."""
    if ground is None or height_m is None:
        return ground
    from pfp_service.core.visibility import (
        AtHeight,
    )  # the compiled core's: the world's inputs import this module

    return AtHeight(ground, height_m)


def ground_zones(ground: Ground | None) -> list[Zone]:
    """The barriers the ground puts in force before any keep-out zone, in their own order."""
    return list(ground.zones) if ground is not None else []


@dataclass(frozen=True, slots=True)
class _GroundSight:
    """A ground's line of sight between two units, with its resolution (``teams.Sight``): each end at its
    ``masts`` height (``None``: the planner's class's)."""

    ground: Ground
    resolution_m: float
    masts: tuple[float | None, float | None] = (None, None)

    def __call__(self, a: tuple[float, float], b: tuple[float, float], clearance_m: float = 0.0) -> bool:
        if self.masts == (None, None):
            return self.ground.sees(a, b, clearance_m)
        return self.ground.sees(a, b, clearance_m, self.masts)

    def between(self, a_m: float | None, b_m: float | None) -> _GroundSight:
        """This sight with its first end ``a_m`` tall and its second ``b_m`` (``None``: the class's)."""
        return _GroundSight(self.ground, self.resolution_m, (a_m, b_m))


def link_sight(ground: Ground | None) -> Sight | None:
    """The line of sight between two units a controller's link needs, or ``None`` without terrain."""
    return _GroundSight(ground, ground.resolution_m) if ground is not None else None
