"""``pfp report`` for teams: per team in the record, its closest pair of members and its robots' link outages.

A team is each ``team/{t}`` put in the record (its last one; a team dissolved
before the end is still reported, over the tracks while it stood or after).
Two members' distance is judged at each report of either, the other's
position interpolated between its own reports (a report before the other's
first or after its last is not judged), as ``pfp inject``'s team
expectations judge.  A robot's link is out while it is further than
``radio_range_m`` from its controller; an outage is a run of such reports,
from the first out to the next in (or to its last report), with its cause:
the range (the record holds no terrain, so line of sight is not judged here:
the planner's own ``lost link`` reasons say it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import msgspec
import numpy as np

from pfp_clients.record.mcapfile import Record
from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.wire.messages import TeamUpdate

__all__ = ["COLUMNS", "Outage", "link_outages", "min_separation", "team_rows", "teams_in"]

COLUMNS = ("team", "members", "min sep m", "pair", "asked m", "link outages", "out s", "longest out")
Track = Sequence[tuple[float, float, float]]  # (t_s, x, y)


def teams_in(rec: Record) -> dict[str, TeamUpdate]:
    """Each team put in the record, as last put (refused puts left out)."""
    decoder = msgspec.json.Decoder(TeamUpdate)
    out: dict[str, TeamUpdate] = {}
    for e in rec.entries:
        try:
            k = keys.parse(e.key)
        except InputError:
            continue
        if k.kind is not keys.KeyKind.TEAM or e.data is None:
            continue
        try:
            out[k.id] = decoder.decode(e.data)
        except (msgspec.ValidationError, msgspec.DecodeError):
            continue
    return out


def _paired(a: Track, b: Track) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(times, a's positions, b's)`` at each of ``a``'s reports within ``b``'s span; ``None``: none."""
    if not a or not b:
        return None
    me, other = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    t = me[:, 0]
    inside = (t >= other[0, 0]) & (t <= other[-1, 0])
    if not inside.any():
        return None
    xy = np.column_stack([np.interp(t, other[:, 0], other[:, 1]), np.interp(t, other[:, 0], other[:, 2])])
    return t[inside], me[inside, 1:], xy[inside]


def min_separation(tracks: dict[str, Track], members: Sequence[str]) -> tuple[float, str]:
    """The least distance between two members over the tracks, and the pair (``inf``, ``-``: never together)."""
    best, pair = math.inf, "-"
    for i, u in enumerate(members):
        for v in members[i + 1 :]:
            for a, b in ((u, v), (v, u)):  # each one's reports, the other interpolated
                got = _paired(tracks.get(a, []), tracks.get(b, []))
                if got is None:
                    continue
                d = float(np.hypot(*(got[1] - got[2]).T).min())
                if d < best:
                    best, pair = d, f"{u}-{v}"
    return best, pair


class Outage(msgspec.Struct, frozen=True):
    """A robot out of its controller's link: from ``start_s`` to ``end_s``, and why."""

    robot: str
    start_s: float
    end_s: float
    cause: str


def link_outages(tracks: dict[str, Track], team: TeamUpdate) -> list[Outage]:
    """Each robot's runs of reports beyond ``radio_range_m`` of its controller, in time order."""
    out: list[Outage] = []
    if team.controller is None:
        return out
    for r in team.robots:
        got = _paired(tracks.get(r, []), tracks.get(team.controller, []))
        if got is None:
            continue
        t, me, ctl = got
        far = np.hypot(*(me - ctl).T)
        start: float | None = None
        worst = 0.0
        for ti, di in zip(t, far):
            if di > team.radio_range_m:
                start = float(ti) if start is None else start
                worst = max(worst, float(di))
            elif start is not None:
                out.append(Outage(r, start, float(ti), _range(worst, team)))
                start, worst = None, 0.0
        if start is not None:
            out.append(Outage(r, start, float(t[-1]), _range(worst, team)))
    return sorted(out, key=lambda o: o.start_s)


def _range(worst: float, team: TeamUpdate) -> str:
    return f"range: {worst:,.0f} m from {team.controller}, radio range {team.radio_range_m:,.0f} m"


def team_rows(rec: Record, tracks: dict[str, Track]) -> tuple[list[tuple[str, ...]], list[Outage]]:
    """The teams table (header first; just the header when the record has no team) and every outage."""
    rows: list[tuple[str, ...]] = [COLUMNS]
    outages: list[Outage] = []
    for tid, team in sorted(teams_in(rec).items()):
        members = team.units()
        sep, pair = min_separation(tracks, members)
        gone = link_outages(tracks, team)
        outages += gone
        total = sum(o.end_s - o.start_s for o in gone)
        longest = max((o.end_s - o.start_s for o in gone), default=0.0)
        rows.append(
            (
                tid,
                " ".join(members),
                "inf" if math.isinf(sep) else f"{sep:.2f}",
                pair,
                "-" if team.separation_m is None else f"{team.separation_m:g}",
                str(len(gone)) if team.robots else "-",
                f"{total:.1f}" if team.robots else "-",
                f"{longest:.1f}" if team.robots else "-",
            )
        )
    return rows, outages
