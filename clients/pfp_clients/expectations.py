"""A script's expectations judged against what was watched: ``judge`` and the report it fills.

``pfp inject`` (``inject``) runs the timeline and watches the units (``watch.Watch``); each
``expect`` entry is then judged here (arrived in time, kept its clearance, never entered a
zone while it was in force), the same whether the script ran live or against a scenario.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pfp_clients import team_expectations as team
from pfp_clients.script import Expect, Script, Step
from pfp_clients.watch import Watch
from pfp_service.coords import Coords

__all__ = ["Fired", "InjectReport", "Verdict", "ZoneVersion", "judge"]


@dataclass(frozen=True)
class Fired:
    """A timeline entry that fired: when (script seconds and wall clock), what, and where its trigger unit was."""

    index: int
    t_s: float
    wall_s: float
    step: Step
    where: tuple[float, float] | None = None


@dataclass(frozen=True)
class Verdict:
    expect: Expect
    held: bool
    detail: str


@dataclass
class InjectReport:
    """What happened: actions fired, entries that never fired, verdicts, and the watch itself."""

    script: Script
    fired: list[Fired]
    unfired: list[int]
    verdicts: list[Verdict]
    watch: Watch
    t_s: float
    t0_wall_s: float
    speed_up: float
    reason: str = ""
    lines: list[str] = field(default_factory=list)
    coords: Coords = field(default_factory=Coords)  # how its lines show positions

    @property
    def ok(self) -> bool:
        return not self.unfired and all(v.held for v in self.verdicts)


@dataclass(frozen=True)
class ZoneVersion:
    """One shape of a zone the script put, in force over ``[start_s, end_s)``."""

    zone_id: str
    zone: Any  # core.zones.Zone
    start_s: float
    end_s: float = math.inf


def _never_enters(e: Expect, watch: Watch, zones: list[ZoneVersion]) -> Verdict:
    """Every segment of the unit's track begun while a version of the zone was in force, checked exactly."""
    from pfp_service.core.zones import track_enters

    versions = [v for v in zones if v.zone_id == e.never_enters]
    track = watch.tracks.get(e.unit or "", [])
    if not versions:
        return Verdict(e, False, f"zone {e.never_enters} was never put")
    if len(track) < 2:
        return Verdict(e, False, "too few states of the unit were seen to judge")
    checked = 0
    for v in versions:
        idx = [i for i, (t, _x, _y) in enumerate(track) if v.start_s <= t < v.end_s]
        if not idx:
            continue
        first, last = max(idx[0] - 1, 0), min(idx[-1] + 1, len(track) - 1)  # the segments into and out of it
        pts = [(x, y) for _t, x, y in track[first : last + 1]]
        checked += len(pts) - 1
        if len(pts) > 1 and track_enters([v.zone], pts) is not None:
            for t, x, y in track[first : last + 1]:
                if v.zone.contains(x, y):
                    return Verdict(e, False, f"entered zone {v.zone_id} at ({x:.2f}, {y:.2f}), t={t:.1f} s")
            return Verdict(e, False, f"a segment of the track crossed zone {v.zone_id}")
    if checked == 0:
        return Verdict(e, False, f"{e.unit} was not seen while zone {e.never_enters} was in force")
    return Verdict(e, True, f"{checked} track segments checked, none touches it")


def _team_arrives(e: Expect, watch: Watch, members: tuple[str, ...]) -> Verdict:
    """Every member of ``e.team`` arrived within ``e.arrives_within_s``: the team's time is its last member's."""
    assert e.arrives_within_s is not None
    if not members:
        return Verdict(e, False, f"team {e.team} has no members")
    late = [u for u in members if u not in watch.arrived_at_s]
    if late:
        last = watch.statuses.get(late[0], "never heard of")
        return Verdict(e, False, f"{late[0]} not arrived (last status: {last})")
    t, u = max((watch.arrived_at_s[u], u) for u in members)
    return Verdict(e, t <= e.arrives_within_s, f"arrived at {t:.1f} s (the last, {u})")


def judge(
    e: Expect,
    watch: Watch,
    zones: list[ZoneVersion] | None = None,
    teams: dict[str, tuple[str, ...]] | None = None,
) -> Verdict:
    """Whether one expectation held, from what ``watch`` saw (and the zones and teams the script put)."""
    if e.team is not None:
        return _team_arrives(e, watch, (teams or {}).get(e.team, ()))
    assert e.unit is not None
    if e.never_enters is not None:
        return _never_enters(e, watch, zones or [])
    other = e.keeps_from or e.only_cleared_by or e.link_to
    if other is not None:  # a team's: judged on the two units' tracks
        check = (
            team.keeps_from if e.keeps_from else team.only_cleared_by if e.only_cleared_by else team.link_to
        )
        held, detail = check(e, watch.tracks.get(e.unit, []), watch.tracks.get(other, []))
        return Verdict(e, held, detail)
    if e.arrives_within_s is not None:
        t = watch.arrived_at_s.get(e.unit)
        if t is None:
            last = watch.statuses.get(e.unit, "never heard of")
            return Verdict(e, False, f"not arrived (last status: {last})")
        return Verdict(e, t <= e.arrives_within_s, f"arrived at {t:.1f} s")
    assert e.min_clearance_m is not None
    if not watch.tracks.get(e.unit):
        return Verdict(e, False, "no state of the unit was seen")
    c = watch.clearance(e.unit, e.to)
    if math.isinf(c):
        what = e.to or "any threat"
        return Verdict(e, False, f"{what} was never in force while {e.unit} was seen")
    return Verdict(e, c >= e.min_clearance_m, f"min clearance {c:.2f} m")
