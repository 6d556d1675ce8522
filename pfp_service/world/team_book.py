"""The world's teams: the teams in force, their leads' tracks, and the roles' verdicts applied to directions.

``TeamBook.put`` takes a team only when it agrees with the teams in force
(``TeamIndex``: a unit in two teams, a cycle of leads); ``judge`` runs
after the planner's directions are computed and rewrites a member's
direction by its roles (``teams.lead``, ``teams.follow``, ``teams.link``):
held (a zero vector, ``reach_m`` 0) or sent another way, the reason saying
which team and why.  The planner's step is what the roles judge: a step cut
short stays on the planner's line; a role that sends a unit elsewhere sends
it along ground the lead crossed, to the main element's route, or back
towards its controller.  Pure: positions come from the world's records.

The team's ``separation_m`` is kept here (``separation``, ``dispersed``) for the dispersion
term between friendly units to read; this book applies no separation itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

from pfp_service.core.zones import ZoneSet
from pfp_service.errors import InputError
from pfp_service.wire import Direction, DirectionStatus, Goal, Progress
from pfp_service.wire.messages import TeamIndex, TeamSummary, TeamUpdate
from pfp_service.world import team_goal
from pfp_service.world import team_leads as leads
from pfp_service.world import team_lines as lines
from pfp_service.world import team_link as link_memory
from pfp_service.world import team_masts as masts
from pfp_service.world import team_place as places
from pfp_service.world import team_steps as steps
from pfp_service.world import teams as roles
from pfp_service.world.events import TeamPut, TeamRemoved
from pfp_service.world.neighbours import FleetKey, Reports
from pfp_service.world.team_tracks import MAX_TRACK_POINTS, LeadTracks
from pfp_service.world.teams import Point, Polyline, Sight, Verdict
from pfp_service.world.units import UnitRecord

__all__ = ["MAX_TRACK_POINTS", "TeamBook"]


class TeamBook:
    """The teams in force, keyed by id, and what their roles need remembered: each lead's track."""

    def __init__(
        self,
        sight: Sight | None = None,
        seen: Callable[[], object] | None = None,
        reports: Reports | None = None,
    ) -> None:
        self.sight = sight  # line of sight over the world's terrain, for the controllers' links (fixed)
        self.teams: dict[str, TeamUpdate] = {}
        # team -> its lead's positions since the team was put, looked at for the leads that moved (``reports``)
        self._leads = LeadTracks(reports)
        self.tracks = self._leads.tracks
        self._of: dict[str, list[str]] = {}  # unit -> the teams it is in
        self._checks = TeamIndex()  # the teams in force, as the checks across teams read them
        self.held: set[str] = set()  # units the last ``judge`` held (a hold is not a stop)
        # robots whose controller the last ``judge`` held for their link, and controllers a robot's link
        # held: each closes on the other, or both would hold for ever (``_closing``)
        self.waits: set[str] = set()
        self.pulls: dict[str, set[str]] = {}  # controller -> the robots their link held
        self._pulled: dict[str, set[str]] = {}
        self._waited: set[str] = set()  # ... and the ``judge`` before it (a robot before its controller)
        self.said: dict[str, str] = {}  # unit -> what its roles last said of its direction, if anything
        self._placing: dict[str, Goal] = {}  # a team goal just put: each member's place, for the world to set
        self.sent: dict[str, Direction] = {}  # member -> its direction last judged (a preview's first move)
        # team -> its track as a polyline and the list it was made of: grown as that list grows, made
        # afresh when the track is another list (trimmed, a new lead, a preview's)
        self._lines: dict[str, tuple[list[Point], Polyline]] = {}
        self._grown: dict[str, lines.Grown] = {}  # team -> the arrays its line is a view of (``team_lines``)
        self._columns: dict[str, list[TeamUpdate]] = {}  # unit -> ``columns``, until the teams change
        self._dispersed: dict[str, tuple[str, float] | None] = {}  # unit -> ``dispersed``, likewise
        self._leading: dict[str, Verdict] = {}  # team -> its lead's verdict in this ``judge`` (team_leads)
        # the robots' breadcrumbs, and the runs between reports of the units in a link
        self.trails = link_memory.Trails()
        self._links: set[str] = set()  # the units in a link: robots and their controllers
        self._controls: set[str] = set()  # the controllers with robots
        self._now: float | None = None  # the time of the ``judge`` under way
        self.version = 0  # bumped by every team put or removed: what a cache of ``dispersed`` keys on
        self._seen = seen  # the units' ``Units.version``: ``where``
        self._reports = reports  # the world's reports (``neighbours.Reports``), in ``where``'s key

    def apply(self, inp: TeamPut | TeamRemoved) -> tuple[InputError | None, set[str]]:
        """A team put or dissolved: why it is refused (``None``: taken), and the units whose roles changed."""
        old = self.teams.get(inp.team)
        units = set(old.units()) if old is not None else set()
        if isinstance(inp, TeamRemoved):
            self.remove(inp.team)
            return None, units
        err = self.put(inp.team, inp.update)
        if err is None and team_goal.placing_changed(old, inp.update):
            self._placing.update(team_goal.places(inp.update))
        return (err, set()) if err is not None else (None, units | set(inp.update.units()))

    def placed(self, units: Mapping[str, UnitRecord]) -> list[tuple[str, Goal]]:
        """The places a team goal just put gives its members, to be set as their goals: once each, and
        none a member already has (a restored or shared mission for the very place stands)."""
        out = [(u, g) for u, g in self._placing.items() if (r := units.get(u)) is None or r.goal != g]
        self._placing = {}
        return out

    def columns(self, unit: str) -> list[TeamUpdate]:
        """The teams with followers ``unit`` leads or follows in: its route is priced for them (``team_route``)."""
        got = self._columns.get(unit)
        if got is None:  # asked per unit and report (``team_route``): kept until a team is put or removed
            got = self._columns[unit] = [
                t
                for tid in self._of.get(unit, ())
                if (t := self.teams[tid]).follow and (t.lead == unit or unit in t.follow)
            ]
        return got

    def put(self, tid: str, team: TeamUpdate) -> InputError | None:
        """Take a team (new, or replacing its earlier self); the reason it is refused, with the field, if it is.

        A new team is checked against the teams in force in time of its own size (``TeamIndex``);
        one replaced or removed rebuilds the index.
        """
        old = self.teams.get(tid)
        index = self._checks if old is None else _index_of({k: v for k, v in self.teams.items() if k != tid})
        err = index.problem(team)
        if err is not None:
            return InputError("$." + err.path, err.reason)
        index.add(tid, team)
        self._checks = index
        self.teams[tid] = team
        self._columns, self._dispersed, self.version = {}, {}, self.version + 1
        self._leads.looked.pop(tid, None)  # its lead or corridor may be new: looked at afresh
        if old is None or old.lead != team.lead:
            self.tracks[tid] = []
        if old is None:
            for u in team.units():
                self._of.setdefault(u, []).append(tid)
            self._links |= _linked(team)
            self._controls |= _linked(team) & {team.controller}
        else:
            self._index()
        return None

    def remove(self, tid: str) -> bool:
        """Dissolve a team; whether there was one."""
        if self.teams.pop(tid, None) is None:
            return False
        self._columns, self._dispersed, self.version = {}, {}, self.version + 1
        self.tracks.pop(tid, None)
        self._leads.looked.pop(tid, None)
        self._lines.pop(tid, None)
        self._grown.pop(tid, None)
        self._checks = _index_of(self.teams)
        self._index()
        self.said = {u: why for u, why in self.said.items() if u in self._of}
        self.sent = {u: d for u, d in self.sent.items() if u in self._of}
        return True

    def _index(self) -> None:
        of: dict[str, list[str]] = {}
        links: set[str] = set()
        controls: set[str] = set()
        for tid, team in self.teams.items():
            for u in team.units():
                of.setdefault(u, []).append(tid)
            links |= _linked(team)
            controls |= _linked(team) & {team.controller}
        self._of, self._controls = of, controls
        self.trails.forget(self._links - links)
        self._links = links

    def roles(self, unit: str) -> list[tuple[str, tuple[str, ...]]]:
        """``(team, roles)`` of each team ``unit`` is in."""
        return [(tid, self.teams[tid].roles(unit)) for tid in self._of.get(unit, ())]

    def summaries(self, units: Mapping[str, UnitRecord]) -> list[TeamSummary]:
        """The teams in force by id, each with what its roles last said of its members and its slowest
        member's ETA (``pfp status``)."""
        out = []
        for tid, team in sorted(self.teams.items()):
            eta_s, slowest = team_goal.eta(team, units)
            notes = [f"{u}: {self.said[u]}"[:1024] for u in team.units() if u in self.said]
            out.append(TeamSummary(id=tid, team=team, notes=notes, eta_s=eta_s, slowest=slowest))
        return out

    def separation(self, unit: str) -> float | None:
        """The least distance ``unit``'s team asks its members to keep (``None``: by class): dispersion's seam."""
        for tid in self._of.get(unit, ()):
            if self.teams[tid].separation_m is not None:
                return self.teams[tid].separation_m
        return None

    def dispersed(self, unit: str) -> tuple[str, float] | None:
        """The team ``unit`` is in that sets ``separation_m``, and that separation (dispersion keeps it among
        its members); asked for the whole fleet each tick (the push), so kept until the teams change."""
        kept = self._dispersed
        if unit not in kept:
            if len(kept) > 4096 + 2 * len(self._of):  # units gone since the teams changed: bounded
                kept.clear()
            of = self._of.get(unit, ())
            kept[unit] = next(((t, sep) for t in of if (sep := self.teams[t].separation_m) is not None), None)
        return kept[unit]

    # -- the roles, applied ----------------------------------------------------------
    def judge(
        self,
        directions: Sequence[Direction],
        units: Mapping[str, UnitRecord],
        sight: Sight | None = None,
        zones_of: Callable[[UnitRecord], ZoneSet] | None = None,
        now: float | None = None,
    ) -> list[Direction]:
        """``directions`` with each team member's rewritten by its roles (the rest as they are).

        Args:
            directions: the planner's directions of one batch.
            units: the world's records, for positions, goals, staleness and progress.
            sight: line of sight between two points over the terrain, where there is terrain
                (default: the book's own, the world's terrain's).
            zones_of: the keep-out zones and slope barriers a unit plans round: a role's step goes
                straight to its point, so it is cut short of them (``team_steps.kept_clear``).
            now: the world's time, for how long a robot has held for its link (``team_link.LINK_WAIT_S``);
                ``None``: no wait, a robot crosses a shadow its controller closes on at once.
        """
        sight = sight if sight is not None else self.sight
        if not self.teams:
            return list(directions)
        self._leads.look(self.teams, self._of, units, self.where())
        held_before, self.held = self.held, set()
        self._waited, self.waits = self.waits, set()
        self._pulled, self.pulls = self.pulls, {}
        self._leading = leads.verdicts(self.teams, self._of, directions, units)
        self._now = now
        held = _Either(held_before, self.held)  # not their union: a copy per member is quadratic in the holds
        out = list(directions)
        # controllers first: a robot is then judged against where its controller's step of this batch
        # takes it, not its last one (the two move at once)
        first = [i for i, d in enumerate(directions) if d.unit in self._controls]
        for i in first + [i for i, d in enumerate(directions) if d.unit not in self._controls]:
            d = directions[i]
            rec = units.get(d.unit)
            if d.unit not in self._of or rec is None or rec.position is None:
                continue
            if d.unit in self._links:
                self.trails.moved(d.unit, rec.position)
            judged = self._judged(d, rec, units, held, sight)
            if judged is not d and zones_of is not None and (judged.reach_m or 0.0) > 0.0:
                judged = steps.kept_clear(judged, rec, zones_of(rec))
            out[i] = judged
            self.sent[d.unit] = judged
        return out

    def where(self) -> FleetKey | None:
        """A key (units', teams') that changes whenever a unit's position, staleness, goal or record (``seen``) or
        a team may have: while it stands, no lead has moved (``LeadTracks``) nor dispersion's index; ``None``: unknown.
        With the world's ``Reports`` in it, its readers ask which units reported since they last looked."""
        return FleetKey(self._seen(), self.version, self._reports) if self._seen is not None else None

    def _line(self, tid: str) -> Polyline:
        """The team's track as a polyline, made once for all its followers and grown with the track."""
        track = self.tracks.get(tid, [])
        kept = self._lines.get(tid)
        # its points' count read off its array, not ``len(line)`` (a call): asked per follower and report
        if kept is not None and kept[0] is track and len(kept[1].pts) == len(track):
            return kept[1]  # not grown since (its other followers, or no report of its lead)
        if kept is not None and kept[0] is track and len(kept[1].pts) <= len(track):
            # grown in place (``team_lines``), the numbers of ``extended``
            line, grown = lines.grow(self._grown.get(tid), kept[1], track[len(kept[1].pts) :])
            if grown is not None:
                self._grown[tid] = grown
        else:
            line = Polyline(track)
        self._lines[tid] = (track, line)
        return line

    def _lost(
        self, unit: str | None, units: Mapping[str, UnitRecord], held: _Either, moved: bool = True
    ) -> str:
        """Why ``unit`` cannot be kept to: ``"is lost (...)"``, ``"has stopped"`` (``"has not moved yet"``
        when it is not known to have moved), or ``""``."""
        rec = units.get(unit) if unit is not None else None
        if rec is None or rec.position is None:
            return "is lost (no report)"
        if rec.stale:
            return "is lost (no report for a while)"
        stopped = rec.progress.verdict in (Progress.HOLDING, Progress.STALLED)
        if stopped and unit not in held and rec.last_status is not DirectionStatus.ARRIVED:
            return "has stopped" if moved else "has not moved yet"
        return ""

    def _judged(
        self,
        d: Direction,
        rec: UnitRecord,
        units: Mapping[str, UnitRecord],
        held: _Either,
        sight: Sight | None,
    ) -> Direction:
        at = rec.position
        assert at is not None
        if d.reach_m is None or not (d.vector[0] or d.vector[1]):
            return d  # not moving (arrived, trapped, no goal): nothing to judge
        to = (at[0] + d.vector[0] * d.reach_m, at[1] + d.vector[1] * d.reach_m)
        reasons: list[str] = []
        for tid in self._of[rec.id]:
            team = self.teams[tid]
            for verdict in self._verdicts(tid, team, rec.id, at, to, units, held, sight):
                if verdict.kind == "go":
                    continue
                reasons.append(f"team {tid}: {verdict.reason}")
                if verdict.kind == "hold" or verdict.to is None:
                    self.held.add(rec.id)
                    self.said[rec.id] = "; ".join(reasons)
                    return steps.held(d, self.said[rec.id])
                to = verdict.to
        if not reasons:
            self.said.pop(rec.id, None)
            return d
        self.said[rec.id] = "; ".join(reasons)
        return steps.towards(d, at, to, self.said[rec.id])

    def _verdicts(
        self,
        tid: str,
        team: TeamUpdate,
        unit: str,
        at: Point,
        to: Point,
        units: Mapping[str, UnitRecord],
        held: _Either,
        sight: Sight | None,
    ) -> list[Verdict]:
        """The verdicts of ``unit``'s roles in ``team``, in the order they apply: lead, follow, robot.

        Each is judged on the step the one before left (a lead's place is then checked against the link).
        """
        out: list[Verdict] = []
        # whether no verdict so far holds, kept as they are added: asked per role and member (a
        # micro-optimisation, bench row: BENCHMARKS.md "The judge's members", the judge)
        moving = True
        # a robot's link: each end at its own height (no terrain, no sight line to set heights on)
        linked = masts.pair(sight, units, team, unit) if sight is not None else None
        if unit in team.robots and unit not in team.follow and (unit in self._waited or unit in self.waits):
            ctl = units.get(team.controller) if team.controller is not None else None
            if ctl is not None and ctl.position is not None and math.dist(at, ctl.position) > 1.0:
                v, pull = link_memory.closing_on(self.trails, unit, at, ctl.position, team, linked, self._now)
                if pull:
                    self.pulls.setdefault(str(team.controller), set()).add(unit)
                return [v]
        if unit == team.lead and team.follow:
            got = self._leading.get(tid)  # asked in this judge's one call, which found its main element
            if got is None:
                main = leads.rearmost(team.follow, units)
                if main is None:
                    got = Verdict("hold", None, "waiting: no follower has reported")
                else:
                    got = roles.lead(at, leads.main_route(main), team.standoff_m, main.id)
            out.append(got)
            moving, to = _after(got, moving, to)
        if unit in team.follow and moving:
            lost = self._lost(team.lead, units, held, moved=len(self.tracks.get(tid, ())) > 1)
            me = units.get(unit)
            goal = me.goal.position if me is not None and me.goal is not None else None
            v = roles.follow(at, to, self._line(tid), team.corridor_m, str(team.lead), lost, goal)
            out.append(v)
            moving, to = _after(v, moving, to)
        if unit in team.robots and moving:
            ctl = units.get(team.controller) if team.controller is not None else None
            lost = self._lost(team.controller, units, held)
            c_at = ctl.position if ctl is not None else None
            c_dir = self.sent.get(str(team.controller))
            v, pull = link_memory.robot_step(
                self.trails, unit, at, to, team, c_at, lost, linked, c_dir, self._now
            )
            out.append(v)
            moving = v.kind != "hold"
            if pull:
                self.pulls.setdefault(str(team.controller), set()).add(unit)
        if unit == team.controller and moving:
            robots = [
                (r, p) for r in team.robots if (rr := units.get(r)) and (p := rr.position) and _guided(rr)
            ]
            ahead, run = self._ahead(robots), self.trails.run(unit)
            ground = (self._line(tid), team.corridor_m) if unit in team.follow else None
            verdict, robot = places.control(
                at, to, robots, team.radio_range_m, sight, ahead, run, None, ground,
                masts.per_robot(sight, units, unit, robots),
            )  # fmt: skip
            out.append(verdict)
            if verdict.kind == "hold":
                self.waits.add(robot)
                moving = False
        if unit != team.controller:
            return out
        now, was = self.pulls.get(unit), self._pulled.get(unit)
        pulling = (now or set()) | (was or set()) if now or was else None
        if pulling and (not moving or team.lead in pulling):  # its lead waits for it: it goes to it
            return self._closing(tid, team, unit, at, pulling, units, held, sight) or out
        return out

    def _closing(
        self,
        tid: str,
        team: TeamUpdate,
        unit: str,
        at: Point,
        pulling: set[str],
        units: Mapping[str, UnitRecord],
        held: _Either,
        sight: Sight | None,
    ) -> list[Verdict] | None:
        """A controller held while a robot's link holds the robot: a step towards that robot (a follower's on
        the ground its lead cleared, cut where it would break another robot's link), or ``None`` when none
        is needed or none can be taken."""
        for r in sorted(pulling, key=lambda r: (r != team.lead, r)):  # its lead first: cleared ground to it
            rec = units.get(r) if r in team.robots else None
            if rec is None or rec.position is None or not _guided(rec) or math.dist(at, rec.position) <= 1.0:
                continue
            p, why = rec.position, f"closing on {r}, whose link holds it"
            if unit in team.follow:
                lost = self._lost(team.lead, units, held, moved=len(self.tracks.get(tid, ())) > 1)
                v = roles.follow(at, p, self._line(tid), team.corridor_m, str(team.lead), lost, p)
                if v.kind == "hold":
                    continue
                p, why = (v.to, f"{why}; {v.reason}") if v.kind == "to" and v.to is not None else (p, why)
            others = [
                (o, q)
                for o in team.robots
                if o != r and (oo := units.get(o)) and (q := oo.position) and _guided(oo)
            ]
            ground = (self._line(tid), team.corridor_m) if unit in team.follow else None
            v, blocking = places.control(
                at, p, others, team.radio_range_m, sight, self._ahead(others), self.trails.run(unit),
                (r, rec.position), ground, masts.per_robot(sight, units, unit, [*others, (r, rec.position)]),
            )  # fmt: skip
            if v.kind == "hold":
                self.waits.add(blocking)  # the robot whose link keeps it from this one closes on it
            else:
                return [
                    Verdict("to", p, why) if v.kind == "go" else Verdict("to", v.to, f"{why}; {v.reason}")
                ]
        return None

    def _ahead(self, robots: Sequence[tuple[str, Point]]) -> dict[str, Point]:
        """Where each robot's direction takes it by its next report, where that is known."""
        return {r: n for r, p in robots if (n := self.trails.ahead(r, p, self.sent.get(r))) is not None}


class _Either:
    """Membership in either of two sets, without building their union."""

    __slots__ = ("a", "b")

    def __init__(self, a: set[str], b: set[str]) -> None:
        self.a, self.b = a, b

    def __contains__(self, unit: object) -> bool:
        return unit in self.a or unit in self.b


def _index_of(teams: Mapping[str, TeamUpdate]) -> TeamIndex:
    index = TeamIndex()
    for tid, team in teams.items():
        index.add(tid, team)
    return index


def _linked(team: TeamUpdate) -> set[str]:
    """The units of ``team`` in a controller's link: its robots and their controller."""
    return {team.controller, *team.robots} if team.controller is not None and team.robots else set()


def _guided(rec: UnitRecord) -> bool:
    """Whether a robot is live and on its way: one arrived, trapped or without a goal cannot close on its controller."""
    done = rec.last_status in (DirectionStatus.ARRIVED, DirectionStatus.TRAPPED)
    return rec.position is not None and not rec.stale and rec.goal is not None and not done


def _after(v: Verdict, moving: bool, to: Point) -> tuple[bool, Point]:
    """Whether no verdict holds and where the step ends, once ``v`` is added to verdicts of which none held
    (``moving``) and whose step ended at ``to``."""
    if v.kind == "hold":
        return False, to
    return moving, v.to if v.kind == "to" and v.to is not None else to
