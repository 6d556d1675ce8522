"""Dispersion's neighbour index over the fleet: built once per change of where the units are, not per ``apply``.

Every unit the world holds a fresh position for is in the index (guided,
arrived, without a goal: a friendly unit is in the way whatever it is
doing), with its separation by class, its team's separation and its goal
(``core.dispersion.NeighbourIndex``).  A contingency's wave goes out a share
an ``apply`` (``wave``), and each share's push asks for that index: arrays
and a k-d tree the size of the fleet, for the share's 64 units.  Between two
shares nothing it is built from need have changed -- the units' positions,
staleness and goals and the records themselves (``units.Units.version``),
and the teams that set a separation (``TeamBook.version``) -- so
``FleetIndex`` keeps it while that key stands and hands it back as new
(``NeighbourIndex.unasked``: the share's own queries are asked afresh, as on
a new index, so a push and its right of way are the same numbers).
``fleet_index`` is the plain computation it stands for.  A live tick's
reports move a quarter of the fleet and change nothing else the index is
built from: then the kept arrays are taken again with the reported rows
moved, and only the points are new, the k-d tree too once a unit has gone far
from where it holds it (``_moved``; ``NeighbourIndex``'s ``moved_from``).  With a key
in two parts (``FleetKey``: the units', the teams'), the same records under the
same teams are not asked their teams again.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np

from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.units import UnitRecord

__all__ = ["TEAM_WIDEST", "Fleet", "FleetIndex", "FleetKey", "TeamOf", "fleet_index"]

# a team's separation_m is kept up to this many times the widest class's: every unit's neighbour search
# reaches two of the widest separations, so a hostile 100 km would make every pair a neighbour
TEAM_WIDEST = 4.0

# the team a unit is in that sets a separation, and that separation (``TeamBook.dispersed``), or None
TeamOf = Callable[[str], "tuple[str, float] | None"]
# the index, the records of its rows in order, and each unit's row
Fleet = tuple[NeighbourIndex, list[UnitRecord], dict[str, int]]
# what an index was built from: its rows' records, their positions, goals and teams (``_moved``)
_Built = tuple[list[UnitRecord], list[object], list[object], "list[tuple[str, float] | None] | None"]


class FleetKey(NamedTuple):
    """A key in two parts for ``FleetIndex``'s ``version``: ``units`` changes whenever a unit's position,
    staleness, goal or record may have, ``teams`` whenever what ``team_of`` says of a unit may have
    (``TeamBook.where``).  While ``teams`` stands, the same records are in the same teams."""

    units: object
    teams: object


def fleet_index(
    units: Mapping[str, UnitRecord],
    settings: DispersionSettings,
    team_of: TeamOf | None = None,
    seps: dict[str, float] | None = None,
) -> Fleet:
    """The neighbour index of every unit in ``units`` with a fresh position, built afresh.

    Args:
        units: the world's records, in their order (a row's number is its place among the fresh ones).
        settings: the separations by class.
        team_of: each unit's team that sets a separation (``None``: no teams).
        seps: each unit's separation by class, kept between calls (the settings fix it); filled here.

    Raises:
        ValueError: a position the k-d tree refuses (the push then goes without dispersion).
    """
    recs = _fresh(units)
    return _built(recs, _teams(recs, team_of), settings, {} if seps is None else seps)


def _fresh(units: Mapping[str, UnitRecord]) -> list[UnitRecord]:
    """The units in the index, in its rows' order: those with a fresh position."""
    return [r for r in units.values() if r.position is not None and not r.stale]


def _teams(recs: list[UnitRecord], team_of: TeamOf | None) -> list[tuple[str, float] | None] | None:
    return [team_of(r.id) for r in recs] if team_of is not None else None


def _built(
    recs: list[UnitRecord],
    teams: list[tuple[str, float] | None] | None,
    settings: DispersionSettings,
    seps: dict[str, float],
) -> Fleet:
    """``fleet_index`` of ``recs`` (``_fresh``), each in ``teams`` (``_teams``)."""
    row = {r.id: k for k, r in enumerate(recs)}
    n = len(recs)
    sep = settings.separation
    team, team_sep = None, None
    if teams is not None and any(t is not None for t in teams):
        names = {t[0]: k for k, t in enumerate(sorted({t for t in teams if t is not None}))}
        team = np.fromiter((-1 if t is None else names[t[0]] for t in teams), dtype=np.intp, count=n)
        most = TEAM_WIDEST * max(settings.separation_m.values())  # the search's reach grows with it
        team_sep = np.fromiter(
            (math.nan if t is None else min(t[1], most) for t in teams), dtype=float, count=n
        )
    goals = np.array(
        [r.goal.position if r.goal is not None else (math.nan, math.nan) for r in recs], dtype=float
    ).reshape(-1, 2)
    index = NeighbourIndex(
        np.array([r.position for r in recs], dtype=float).reshape(-1, 2),
        np.fromiter(
            (seps[u] if (u := r.id) in seps else seps.setdefault(u, sep(u)) for r in recs),
            dtype=float,
            count=n,
        ),
        team,
        team_sep,
        goals,
    )
    return index, recs, row


class FleetIndex:
    """``fleet_index``, kept while ``version`` gives the same key (``None``, or no ``version``: built each call).

    Args:
        settings: the separations by class.
        units: the world's records.
        team_of: as ``fleet_index``'s.
        version: a key that changes whenever anything the index is built from may have: the units'
            positions, staleness, goals or records, or the teams' separations.
    """

    def __init__(
        self,
        settings: DispersionSettings,
        units: Mapping[str, UnitRecord],
        team_of: TeamOf | None = None,
        version: Callable[[], object] | None = None,
    ) -> None:
        self.settings = settings
        self._units = units
        self._team_of = team_of
        self._version = version
        self._seps: dict[str, float] = {}  # each unit's separation, by its class: fixed by the settings
        self._kept: Fleet | None = None
        self._key: object = None
        # what the kept index was built from: its rows' records, positions, goals and teams (``_moved``)
        self._from: _Built | None = None

    def __call__(self) -> Fleet:
        """The fleet's index as if new-built, its rows' records and each unit's row."""
        key = self._version() if self._version is not None else None
        kept = self._kept
        if kept is not None and key is not None and key == self._key:
            kept[0].unasked()
            return kept
        self._kept, was = None, self._from  # a build that raises keeps nothing
        self._from = None
        if len(self._seps) > 2 * len(self._units) + 64:  # forgotten units' go (bounded by the fleet)
            self._seps.clear()
        recs = _fresh(self._units)
        # the teams as they were, while the teams' part of the key stands: right if the records are the same
        # ones (``_moved`` says so), else asked afresh.  A micro-optimisation (bench row: ``python -m
        # benchmarks._march_world --tick 16``, the fleet index): ``team_of`` is a call per unit
        stand = was is not None and was[3] is not None and _teams_stand(self._key, key)
        teams = was[3] if stand and was is not None else _teams(recs, self._team_of)
        moved = _moved(was, recs, teams) if kept is not None and key is not None else None
        if stand and moved is None:  # other records (or none kept): their teams as ``team_of`` says
            teams = _teams(recs, self._team_of)
        if kept is not None and moved is not None:
            self._kept = _moved_index(kept, recs, moved)
        else:
            self._kept = _built(recs, teams, self.settings, self._seps)
        self._key = key
        if key is not None:
            self._from = (recs, [r.position for r in recs], [r.goal for r in recs], teams)
        return self._kept


def _teams_stand(was: object, key: object) -> bool:
    """Whether two keys' teams' parts are the same (both ``FleetKey``s)."""
    return isinstance(was, FleetKey) and isinstance(key, FleetKey) and was.teams == key.teams


def _moved(
    was: _Built | None,
    recs: list[UnitRecord],
    teams: list[tuple[str, float] | None] | None,
) -> list[int] | None:
    """The rows whose unit reported a new position since the index ``was`` built from, when nothing else
    it is built from changed (the same records in the same rows, their goals, their teams); else ``None``."""
    if was is None:
        return None
    recs_was, at_was, goals_was, teams_was = was
    if len(recs) != len(recs_was) or teams != teams_was:
        return None
    # one pass, not a check of every record and then a look at every position: a micro-optimisation
    # (bench row: ``python -m benchmarks._march_world --tick 16``, the fleet index)
    moved = []
    for k, (r, b, g, p) in enumerate(zip(recs, recs_was, goals_was, at_was)):
        if r is not b or r.goal is not g:
            return None
        if r.position is not p:
            moved.append(k)
    return moved


def _moved_index(kept: Fleet, recs: list[UnitRecord], moved: list[int]) -> Fleet:
    """``kept``'s index with the ``moved`` rows at their units' new positions: its other arrays are the
    very ones a build makes (the same records, goals and teams), its points new, its k-d tree kept while
    the moves are small.  A micro-optimisation (bench row: ``python -m benchmarks._march_world``, a
    tick): a live tick moves a quarter of the fleet, and a build walks every record for every array."""
    index, _, row = kept
    points = index.points.copy()
    if moved:
        points[moved] = np.array([recs[k].position for k in moved], dtype=float).reshape(-1, 2)
    return (
        NeighbourIndex(points, index.seps, index.team, index.team_sep, index.goals, moved_from=index),
        recs,
        row,
    )
