"""The teams' leads' tracks: each lead's positions since its team was put, looked at for the leads that moved.

A lead's position joins its team's track once it has moved a sixteenth of
the corridor (a chord cuts a bend by less than its reports do); the
followers keep to the ground the track covers (``teams.follow``).  The team
book looks before each ``judge`` (``LeadTracks.look``).  Nothing is looked
at while no unit reported, went stale or was dropped and no team changed
(``TeamBook.where``: a wave's shares); and when reports alone changed the
units since the last look (``neighbours.Reports.since``) and no team did,
only the leads among the reported units are looked at, not every team's: a
live tick of a few reports moves a few leads (issue 33, BENCHMARKS.md "The
live ticks' work over the fleet").  Each team's track is its own, so the
teams looked at and their order change nothing but the cost.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from pfp_service.wire.messages import TeamUpdate
from pfp_service.world import teams as roles
from pfp_service.world.neighbours import FleetKey, Mark, Reports
from pfp_service.world.teams import Point
from pfp_service.world.units import UnitRecord

__all__ = ["MAX_TRACK_POINTS", "LeadTracks"]

MAX_TRACK_POINTS = 4096  # a lead's track kept at most: the part behind every follower goes first


class LeadTracks:
    """Each team's lead's track (``tracks``: team -> points), and where its lead was last looked at."""

    def __init__(self, reports: Reports | None = None) -> None:
        self.tracks: dict[str, list[Point]] = {}  # team -> its lead's positions since the team was put
        # team -> its lead's position ``look`` last looked at: unmoved, a look goes no further
        self.looked: dict[str, object] = {}
        self._reports = reports
        self.key: object = None  # ``TeamBook.where`` when ``look`` last looked
        self._mark: Mark | None = None  # ``reports``' mark then

    def look(
        self,
        teams: Mapping[str, TeamUpdate],
        of: Mapping[str, list[str]],
        units: Mapping[str, UnitRecord],
        key: object,
    ) -> None:
        """Each lead's position joins its team's track once it has moved a sixteenth of the corridor.

        Args:
            teams: the teams in force.
            of: unit -> the teams it is in.
            units: the world's records.
            key: ``TeamBook.where`` now (``None``: unknown, every team looked at).
        """
        if key is not None and key == self.key:
            return  # no unit reported, went stale or was dropped, no team changed: no lead has moved
        looked = self.looked
        for tid in self._moved(teams, of, key):
            team = teams[tid]
            rec = units.get(team.lead) if team.lead is not None else None
            if rec is None or rec.position is None or rec.stale or looked.get(tid) is rec.position:
                continue  # no lead to track, or the very position looked at before (a report makes a new one)
            looked[tid] = rec.position
            track = self.tracks.setdefault(tid, [])
            if not track or math.dist(track[-1], rec.position) >= max(team.corridor_m / 16.0, 0.1):
                track.append(rec.position)
            if len(track) > MAX_TRACK_POINTS:
                self._trim(tid, team, units)
        self.key = key
        self._mark = self._reports.mark() if self._reports is not None else None

    def _moved(
        self, teams: Mapping[str, TeamUpdate], of: Mapping[str, list[str]], key: object
    ) -> Iterable[str]:
        """The teams whose lead may have moved since the last look: those led by a unit reported since,
        when reports alone changed the units and no team changed (``Reports.since``); else every team."""
        was = self.key
        got = None
        if (
            self._reports is not None
            and isinstance(key, FleetKey)
            and isinstance(was, FleetKey)
            and key.teams == was.teams
        ):
            got = self._reports.since(self._mark)
        if got is None:
            return teams
        out: dict[str, None] = {}  # in the order reported, each once
        for r in got:
            for tid in of.get(r.id, ()):
                if teams[tid].lead == r.id:
                    out[tid] = None
        return out

    def _trim(self, tid: str, team: TeamUpdate, units: Mapping[str, UnitRecord]) -> None:
        """Drop the track behind the rearmost follower; then every other point, if it is still too long."""
        track = self.tracks[tid]
        behind = [
            roles.project(r.position, track)[0]
            for f in team.follow
            if (r := units.get(f)) is not None and r.position is not None
        ]
        s = min(behind, default=0.0)
        start = 0
        for i in range(1, len(track)):
            s -= math.dist(track[i - 1], track[i])
            if s < team.corridor_m:
                break
            start = i
        track = track[start:]
        self.tracks[tid] = track if len(track) <= MAX_TRACK_POINTS else track[::2] + track[-1:]
