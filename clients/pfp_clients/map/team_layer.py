"""What the map shows of teams: each team's roles, and its lead's track (the cleared corridor), sans-I/O.

The model (``model``) hands it each team put or dissolved on ``team/{t}``
(and the teams a planner's world reply holds) and every unit's reported
position; ``take`` gives the teams changed since the last call.  The page
(``static/teams.js``) draws a line from each lead to its followers, each
controller's radio circle, and the cleared corridor: the lead's track since the
map heard of the team, ``corridor_m`` wide.  A point joins a track once the lead
has moved a sixteenth of the corridor (as the planner keeps it: ``world.team_book``),
and a track keeps its last ``TRACK_MAX`` points.
"""

from __future__ import annotations

import math
from typing import Any

import msgspec

from pfp_service.wire.messages import TeamUpdate

__all__ = ["TRACK_MAX", "TeamLayer"]

TRACK_MAX = 2000


class TeamLayer:
    """The teams heard, each lead's track, and which changed since ``take``."""

    def __init__(self) -> None:
        self.teams: dict[str, TeamUpdate] = {}
        self.tracks: dict[str, list[tuple[float, float]]] = {}
        self._dirty: set[str] = set()
        self._removed: set[str] = set()

    def put(self, tid: str, team: TeamUpdate | None) -> None:
        """A team put, or dissolved (``None``); its lead's track restarts when the lead changes."""
        old = self.teams.get(tid)
        if team is None:
            if self.teams.pop(tid, None) is not None:
                self.tracks.pop(tid, None)
                self._removed.add(tid)
                self._dirty.discard(tid)
            return
        self.teams[tid] = team
        if old is None or old.lead != team.lead:
            self.tracks[tid] = []
        self._dirty.add(tid)
        self._removed.discard(tid)

    def moved(self, unit: str, at: tuple[float, float]) -> None:
        """A unit reported ``at``: a lead's track grows, and any team it is in is redrawn."""
        for tid, team in self.teams.items():
            if unit == team.lead:
                track = self.tracks.setdefault(tid, [])
                if not track or math.dist(track[-1], at) >= max(team.corridor_m / 16.0, 0.1):
                    track.append((round(at[0], 2), round(at[1], 2)))
                    del track[:-TRACK_MAX]
            if unit in team.units():
                self._dirty.add(tid)

    def view(self, tid: str) -> dict[str, Any]:
        team = self.teams[tid]
        return {"id": tid, **msgspec.to_builtins(team), "track": list(self.tracks.get(tid, []))}

    def take(self) -> dict[str, Any]:
        """``{"teams": {id: view}, "teams_removed": [...]}`` of what changed (each key only when it did)."""
        out: dict[str, Any] = {}
        if self._dirty:
            out["teams"] = {tid: self.view(tid) for tid in self._dirty}
        if self._removed:
            out["teams_removed"] = sorted(self._removed)
        self._dirty, self._removed = set(), set()
        return out

    def all(self) -> dict[str, Any]:
        return {tid: self.view(tid) for tid in self.teams}
