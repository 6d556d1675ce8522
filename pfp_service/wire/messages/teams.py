"""A team on the wire (``mumt/{m}/team/{t}``): its members, their roles and its distances, and the checks across teams.

A team says who leads (``lead``, a scout ahead of the main element), who
follows (``follow``: they enter only ground the lead has crossed), who
controls robots (``controller`` and its ``robots``) and the distances those
roles keep.  ``TeamUpdate`` checks one team by itself as it decodes;
``team_problems`` checks a set of teams against each other (and against the
units known, where they are): pure, it returns rejections and never raises.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from typing import Annotated

from msgspec import Meta

from pfp_service.constraints import Id
from pfp_service.errors import InputError
from pfp_service.wire.messages.structs import Goal, _Message

__all__ = [
    "MAX_TEAM_MEMBERS",
    "RADIO_RANGE_MAX_M",
    "TeamIndex",
    "TeamProblem",
    "TeamUpdate",
    "team_problems",
]

MAX_TEAM_MEMBERS = 256  # ids in one list of a team; a platoon's vehicles, not a fleet
# The longest distance a team keeps: a radio's reach over open ground, not a satellite link's.
RADIO_RANGE_MAX_M = 100_000.0
Distance = Annotated[float, Meta(gt=0.0, le=RADIO_RANGE_MAX_M)]
Ids = Annotated[list[Id], Meta(max_length=MAX_TEAM_MEMBERS)]
Offset = Annotated[float, Meta(ge=-RADIO_RANGE_MAX_M, le=RADIO_RANGE_MAX_M)]
Offsets = Annotated[dict[Id, tuple[Offset, Offset]], Meta(max_length=MAX_TEAM_MEMBERS)]


class TeamUpdate(_Message, frozen=True, kw_only=True):
    """A team, put on ``mumt/{m}/team/{t}`` (the id is the key's last chunk); a DELETE dissolves it.

    Attributes:
        members: the team's units beyond those named in a role (every unit named anywhere is a member).
        separation_m: the least distance kept between two members; absent, by their class.
        lead: the scout: it moves ahead of the main element (``follow``) along its route by ``standoff_m``
            and waits when the main element falls behind.
        follow: the main element: each enters only ground ``lead`` has crossed, a corridor ``corridor_m``
            wide along the lead's track; if the lead is lost or stops, each holds and says why.
        standoff_m: how far ahead of the main element the lead keeps, metres along its route.
        corridor_m: the width of the cleared corridor, metres (the lead's track, ``corridor_m / 2`` either side).
        controller: the unit that controls ``robots``.
        robots: each keeps within ``radio_range_m`` of ``controller`` (and in its line of sight over terrain);
            a step that would break the link is not taken.
        radio_range_m: the controller's radio reach, metres.
        goal: the team's goal: each member is given its place by it (``teams.places``): a member in
            ``offsets`` the goal moved by its offset, every other in column order (the lead first, then
            the followers, then the rest), the ``i``-th arriving within ``i * spacing_m`` more of the goal.
        offsets: ``[east, north]`` metres from the team's goal to a member's place (a formation).
        spacing_m: the distance between two places in the column; absent, ``separation_m``, else 50 m.
    """

    members: Ids = []
    separation_m: Distance | None = None
    lead: Id | None = None
    follow: Ids = []
    standoff_m: Distance = 300.0
    corridor_m: Distance = 30.0
    controller: Id | None = None
    robots: Ids = []
    radio_range_m: Distance = 1500.0
    goal: Goal | None = None
    offsets: Offsets = {}
    spacing_m: Distance | None = None

    def __post_init__(self) -> None:
        for name in ("members", "follow", "robots"):
            seen: set[str] = set()
            for i, u in enumerate(getattr(self, name)):
                if u in seen:
                    raise ValueError(f"{name}[{i}]: {u!r} is listed twice")
                seen.add(u)
        if self.follow and self.lead is None:
            raise ValueError("follow: followers need a lead whose ground they enter")
        if self.lead is not None and self.lead in self.follow:
            raise ValueError(
                f"follow[{self.follow.index(self.lead)}]: the lead {self.lead!r} cannot follow itself"
            )
        if self.robots and self.controller is None:
            raise ValueError("robots: robots need a controller")
        if self.controller is not None and self.controller in self.robots:
            i = self.robots.index(self.controller)
            raise ValueError(f"robots[{i}]: the controller {self.controller!r} cannot control itself")
        if self.offsets and self.goal is None:
            raise ValueError("offsets: a formation's offsets need the team's goal")
        units = set(self.units())
        for u in self.offsets:
            if u not in units:
                raise ValueError(f"offsets.{u}: {u!r} is not a member of the team")

    def units(self) -> tuple[str, ...]:
        """Every unit of the team, once each: members, then the lead, followers, controller and robots."""
        named = [*self.members, self.lead, *self.follow, self.controller, *self.robots]
        return tuple(dict.fromkeys(u for u in named if u is not None))

    def roles(self, unit: str) -> tuple[str, ...]:
        """What ``unit`` is in this team: ``lead``, ``follow``, ``controller``, ``robot`` or ``member``."""
        out = [
            role
            for role, held in (
                ("lead", unit == self.lead),
                ("follow", unit in self.follow),
                ("controller", unit == self.controller),
                ("robot", unit in self.robots),
            )
            if held
        ]
        return tuple(out) if out else (("member",) if unit in self.members else ())


@dataclass(frozen=True, slots=True)
class TeamProblem:
    """Why a team is refused: the team and the error (its field path within the team, and the reason)."""

    team: str
    error: InputError


def _paths(team: TeamUpdate) -> Iterator[tuple[str, str]]:
    """``(unit, field path)`` for every unit a team names."""
    for name in ("members", "follow", "robots"):
        for i, u in enumerate(getattr(team, name)):
            yield u, f"{name}[{i}]"
    for name in ("lead", "controller"):
        u = getattr(team, name)
        if u is not None:
            yield u, name


class TeamIndex:
    """The teams taken so far, as the checks across teams need them: each unit's team and roles, and who follows whom.

    ``problem`` checks one more team against them in time of its own size, so taking ``n`` teams
    one by one costs ``n`` checks, not ``n**2``.
    """

    def __init__(self) -> None:
        self.where: dict[str, tuple[str, str]] = {}  # unit -> (team, its roles there) of the teams taken
        self.leads: dict[str, set[str]] = {}  # follower -> the leads it follows, over the teams taken

    def problem(self, team: TeamUpdate, known: Collection[str] | None = None) -> InputError | None:
        """Why ``team`` cannot join the teams taken (its field path within the team), or ``None``."""
        for u, path in _paths(team):
            if known is not None and u not in known:
                return InputError(path, f"unknown unit {u!r}")
            held = self.where.get(u)
            if held is None:
                continue
            other, roles = held
            chained = (roles == "lead" and team.roles(u) == ("follow",)) or (
                roles == "follow" and team.roles(u) == ("lead",)
            )
            if not chained:
                return InputError(
                    path, f"{u!r} is already in team {other!r} (as {roles}); a unit is in one team"
                )
        if team.lead is not None:
            for f in team.follow:  # a new edge f -> lead closes a cycle when lead already reaches f
                if _reaches(team.lead, f, self.leads):
                    return InputError("lead", f"a cycle of leads: {team.lead!r} already follows {f!r}")
        return None

    def add(self, tid: str, team: TeamUpdate) -> None:
        """Take ``team`` (checked by ``problem``)."""
        for u in team.units():
            self.where.setdefault(u, (tid, ",".join(team.roles(u))))
        if team.lead is not None:
            for f in team.follow:
                self.leads.setdefault(f, set()).add(team.lead)


def team_problems(teams: Mapping[str, TeamUpdate], known: Collection[str] | None = None) -> list[TeamProblem]:
    """What is wrong across ``teams`` (in their order): one problem per team at most; never raises.

    A team is refused when it names a unit not in ``known`` (when given), puts a unit already in an
    earlier team (but a chain: one team's lead may follow another's), or closes a cycle of leads
    (``a`` follows ``b`` who follows ... ``a``).  Teams refused are left out of the later checks, so
    the first of two clashing teams stands.
    """
    problems: list[TeamProblem] = []
    index = TeamIndex()
    for tid, team in teams.items():
        problem = index.problem(team, known)
        if problem is not None:
            problems.append(TeamProblem(tid, problem))
        else:
            index.add(tid, team)
    return problems


def _reaches(start: str, goal: str, leads: Mapping[str, set[str]]) -> bool:
    """Whether following leads from ``start`` comes to ``goal``."""
    seen, todo = {start}, [start]
    while todo:
        u = todo.pop()
        if u == goal:
            return True
        for nxt in leads.get(u, ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return False
