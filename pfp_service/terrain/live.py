"""Terrain for ``pfp serve``: one DEM loaded at start, placed round the mission origin, as the live world takes it.

``load`` reads the DEM once (through ``planning.prepare``, the very path
``pfp plan --terrain`` takes), over the mission's bounds, or over the whole
DEM when there are none (its box on the plane, shrunk by ``EDGE_SHARE`` so
that every corner lies within it), and with no origin given places the plane
at the DEM's centre (``LiveTerrain.centred``, which the status says).

A ``LiveTerrain`` is what the world's ``settings.terrain`` holds: its
``sight`` (each threat's line of sight, swept at the unit class's height;
a unit of another class sees the same windows at its own, ``core.visibility.AtHeight``) and its
``zones`` (ground steeper than the class's limit, and unknown ground, as
keep-out zones), its ``barriers`` for every class's limit (a unit whose goal
names another class, ``world.mobility``: made when it loads), ``build_barriers``
for any other (an override's, built off the loop and held by the world,
``world.slopes``), and for the status its ``about``: file name, sha256, bounds
in latitude and longitude, resolution.

Passed by name, not by value.  A ``LiveTerrain`` is pickled as the arguments
it was loaded with; a process that has loaded them (the planner, and every
worker forked from its warm fork server) gets the same object back from
``_LOADED``, and any other loads the file again.  A preview's view or a
deliberation chunk then ships a few hundred bytes, never the grid.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pfp_service.core.mobility import CLASS_LIMITS, CLASSES, Mobility
from pfp_service.core.zones import Zone
from pfp_service.geo import Origin
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.link_sight import sees
from pfp_service.terrain.threat_sight import TerrainSight

__all__ = ["BARRIER_SETS", "EDGE_SHARE", "LiveTerrain", "TerrainAbout", "load", "of_grid"]

EDGE_SHARE = 0.01  # of the DEM's span, kept off each of its edges: the plane's box must lie inside it
BARRIER_SETS = 4  # slope limits' barrier sets kept besides the planner's class's: the classes and an override
Bounds = tuple[tuple[float, float], tuple[float, float]]


@dataclass(frozen=True)
class TerrainAbout:
    """What the status says of the terrain (``wire.TerrainInfo``)."""

    file: str
    sha256: str
    south: float
    west: float
    north: float
    east: float
    resolution_m: float
    unit: str  # the mobility class planned for
    centred: bool  # the mission origin is the DEM's centre (none was given)


@dataclass(frozen=True, eq=False)
class LiveTerrain:
    """A DEM placed under a live mission: the threats' line of sight and the slope barriers (``load``)."""

    grid: TerrainGrid
    unit: Mobility
    origin: Origin
    bounds: Bounds  # the planner's bounds: the mission's, or the terrain's extent
    about: TerrainAbout
    zones: tuple[Zone, ...]
    look: TerrainSight
    key: tuple[Any, ...] = ()  # ``load``'s arguments: how it is pickled
    _sets: OrderedDict[int, tuple[Zone, ...]] = field(default_factory=OrderedDict, repr=False)

    def __call__(self, threat: Any, box: tuple[float, float, float, float]) -> Any:
        """Threat ``threat``'s window (a ``core.visibility.Sight``): the terrain is its own sight, so a
        field's ``sight`` pickles by name."""
        return self.look(threat, box)

    @property
    def resolution_m(self) -> float:
        """The grid's cell, metres: what a line of sight over it can tell apart."""
        return self.grid.cell_m

    def barriers(self, max_slope_deg: int | None) -> tuple[Zone, ...]:
        """The barrier zones of a unit climbing ``max_slope_deg`` whole degrees (``None``: the class's,
        ``zones``), made the first time a limit is asked for; the least recently used dropped past
        ``BARRIER_SETS``."""
        if max_slope_deg is None or (self.key and max_slope_deg == self.unit.max_slope_deg):
            return self.zones  # a loaded terrain's zones are its class's barriers (``planning.prepare``)
        got = self._sets.get(max_slope_deg)
        if got is None:
            from pfp_service.terrain.barriers import barrier_zones

            got = self._sets[max_slope_deg] = tuple(barrier_zones(self.grid, float(max_slope_deg)))
            while len(self._sets) > BARRIER_SETS:
                self._sets.popitem(last=False)
        self._sets.move_to_end(max_slope_deg)
        return got

    def build_barriers(self, max_slope_deg: int) -> tuple[Zone, ...]:
        """The barrier zones of a unit climbing ``max_slope_deg`` whole degrees, built now and not kept here
        (0.5-1.3 s over the Jacksboro DEM: the world asks for an override's off the loop, ``world.slopes``,
        and holds it itself)."""
        from pfp_service.terrain.barriers import barrier_zones

        return tuple(barrier_zones(self.grid, float(max_slope_deg)))

    def hold_class_limits(self) -> None:
        """Build the barriers of every class's limit now (``core.mobility.CLASS_LIMITS``), before the
        planner serves: the world plans each unit at one of them, so the loop never builds a set."""
        for limit in CLASS_LIMITS:
            self.barriers(limit)

    def sees(
        self,
        a: tuple[float, float],
        b: tuple[float, float],
        clearance_m: float = 0.0,
        masts: tuple[float | None, float | None] = (None, None),
    ) -> bool:
        """Whether two units at ``a`` and ``b`` see each other over the ground (a controller's link), each as
        high as its ``masts`` entry (``None``: the unit class's height), the sight line ``clearance_m`` clear
        of it (``link_sight.sees``)."""
        own = self.unit.height_m
        a_m, b_m = (own if m is None else m for m in masts)
        return sees(self.grid, a, b, a_m, clearance_m, b_m)

    def over_ground(self, path: Sequence[tuple[float, float]], unit: Mobility | None) -> dict[str, object]:
        """A path's figures over the ground (``planning.over_ground``: elevations, climb, steepest ground and
        the ETA) for a unit of ``unit``'s mobility (``None``: the class's)."""
        from pfp_service.terrain.planning import over_ground

        return over_ground(self.grid, np.asarray(path, dtype=float), self.unit if unit is None else unit)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        if not self.key:
            raise TypeError("a terrain made from a grid (of_grid) is not passed between processes")
        return _restore, self.key


_LOADED: dict[tuple[Any, ...], LiveTerrain] = {}


def _restore(*key: Any) -> LiveTerrain:
    got = _LOADED.get(key)
    return got if got is not None else load(*key)


def _sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load(path: str, origin: Origin | None, bounds: Bounds | None, unit: str = "foot") -> LiveTerrain:
    """The DEM at ``path`` under a mission of ``origin`` (``None``: the DEM's centre) and ``bounds``.

    Once per process and arguments: a second call returns the first's terrain.

    Raises:
        InputError: the DEM cannot be read, placed, or does not cover the bounds (one line, naming the file).
    """
    from pfp_service.terrain.dem import check, info
    from pfp_service.terrain.planning import prepare

    key = (path, origin, bounds, unit)
    if key in _LOADED:
        return _LOADED[key]
    check(path)
    about = info(path)
    s, w, n, e = about.bounds_latlon
    placed = origin if origin is not None else Origin(lat=(s + n) / 2.0, lon=(w + e) / 2.0)
    area = bounds if bounds is not None else _inner_box(placed, about.bounds_latlon)
    ground = prepare(path, placed, [], area, CLASSES[unit])
    (x0, y0), (x1, y1) = ground.bounds
    terrain = LiveTerrain(
        ground.grid,
        ground.unit,
        placed,
        ((x0, y0), (x1, y1)),
        TerrainAbout(
            os.path.basename(path), _sha256(path), s, w, n, e, ground.grid.cell_m, unit, origin is None
        ),
        tuple(ground.zones),
        ground.sight,
        key,
    )
    terrain.hold_class_limits()
    _LOADED[key] = _LOADED[(path, placed, bounds, unit)] = terrain  # asked again with the origin it chose
    return terrain


def _inner_box(origin: Origin, latlon: tuple[float, float, float, float]) -> Bounds:
    """The box on ``origin``'s plane inside the DEM's ``(south, west, north, east)``, ``EDGE_SHARE`` off each edge."""
    s, w, n, e = latlon
    ds, dw = EDGE_SHARE * (n - s), EDGE_SHARE * (e - w)
    corners = [origin.to_local(lat, lon) for lat in (s + ds, n - ds) for lon in (w + dw, e - dw)]
    sw, se, nw, ne = corners[0], corners[1], corners[2], corners[3]
    x0, x1 = max(sw[0], nw[0]), min(se[0], ne[0])
    y0, y1 = max(sw[1], se[1]), min(nw[1], ne[1])
    return ((float(math.ceil(x0)), float(math.ceil(y0))), (float(math.floor(x1)), float(math.floor(y1))))


def of_grid(grid: TerrainGrid, unit: str = "foot", zones: tuple[Zone, ...] = ()) -> LiveTerrain:
    """A terrain straight from a grid, in this process only (the warm-up's and the tests' ground)."""
    ny, nx = grid.shape
    extent = (
        (grid.x0_m, grid.y0_m),
        (grid.x0_m + (nx - 1) * grid.cell_m, grid.y0_m + (ny - 1) * grid.cell_m),
    )
    mob = CLASSES[unit]
    about = TerrainAbout("", "", 0.0, 0.0, 0.0, 0.0, grid.cell_m, unit, False)
    terrain = LiveTerrain(
        grid, mob, Origin(lat=0.0, lon=0.0), extent, about, zones, TerrainSight(grid, mob.height_m)
    )
    terrain.hold_class_limits()
    return terrain
