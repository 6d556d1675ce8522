"""The ground under the live world, as the world takes it: a line of sight for the threats and barriers.

``WorldSettings.terrain`` holds a ``Ground`` (``terrain.live.LiveTerrain``,
loaded by the node before the world starts): every threat's packed row is
masked by its ``sight`` (``core.visibility``), and its ``zones`` (ground too
steep for the mission's unit class, and unknown ground) are in force with the
keep-out zones put on the wire, so the stepper, deliberation and previews
treat them alike, as ``pfp plan --terrain`` does; its ``sees`` is the line of
sight a controller's link keeps to its robots (``team_book``).  None changes
while the planner runs.  The world never reads the DEM: it is handed what it needs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from pfp_service.core.visibility import Window
from pfp_service.core.zones import Zone
from pfp_service.world.teams import Sight

__all__ = ["Ground", "ground_zones", "link_sight", "sight_of"]


class Ground(Protocol):
    """What the world takes from a terrain: a ``core.visibility.Sight`` and the barrier zones."""

    @property
    def zones(self) -> Sequence[Zone]: ...

    def __call__(self, threat: object, box: tuple[float, float, float, float]) -> Window | None: ...

    def sees(self, a: tuple[float, float], b: tuple[float, float], clearance_m: float = 0.0) -> bool: ...

    @property
    def resolution_m(self) -> float: ...


def sight_of(ground: Ground | None) -> Ground | None:
    """The sight a field of the world's threats is built with (the ground itself), or ``None``."""
    return ground


def ground_zones(ground: Ground | None) -> list[Zone]:
    """The barriers the ground puts in force before any keep-out zone, in their own order."""
    return list(ground.zones) if ground is not None else []


@dataclass(frozen=True, slots=True)
class _GroundSight:
    """A ground's line of sight between two units, with its resolution (``teams.Sight``)."""

    ground: Ground
    resolution_m: float

    def __call__(self, a: tuple[float, float], b: tuple[float, float], clearance_m: float = 0.0) -> bool:
        return self.ground.sees(a, b, clearance_m)


def link_sight(ground: Ground | None) -> Sight | None:
    """The line of sight between two units a controller's link needs, or ``None`` without terrain."""
    return _GroundSight(ground, ground.resolution_m) if ground is not None else None
