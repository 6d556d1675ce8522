"""The live world: a sans-I/O state machine of one mission's units, goals, threats and keep-out zones.

In the manner of h11's connection: ``World.apply(inputs, now)`` takes a batch
of frozen input events (``Input``) and returns ``Outputs``: the directions,
events, deliberation jobs (and those cancelled), missions and faults that
must go out.  It reads no socket or file and no clock of its own: ``now`` is
a parameter, and the driver's clock, when passed, is read only to size a
wave's share (``wave.Budget``).
Every decision lives here -- who gets a direction, which event fires and why,
status transitions, expiry, limits, who answers a preview.

``World`` decides; its parts keep the books, each plain data in and out with
its own tests: the records and the threats' field (``world_records``), the
timer heap (``timers``), staleness, forgetting and push re-sends
(``liveness``), cluster ownership (``ownership``), zones put and gone (``zone_puts``), the
limits on rejections and fault lines (``limits``), a unit's mission (``missions``), the reactive step, its look-ahead and dispersion
(``steering``, ``lookahead``, ``dispersion``), the snapshot's pages (``snapshot.page``).  Unbounded
work (look-ahead, escape searches) is deliberation: a ``Job`` whose result is adopted only for the
goal and world still in force.  Bulkheads: ``apply`` is total; a failure belongs to the input, timer
or unit that caused it (rejected on its key, its goal dropped, a ``Fault`` logged at most once a
minute per key); the rest goes out.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

from pfp_service.core import ThreatField
from pfp_service.core.advice import Advice
from pfp_service.errors import InputError
from pfp_service.wire import GOAL_CANCELLED, Direction, Goal, UnitState, WorldSnapshot, keys
from pfp_service.wire import ThreatUpdate as ThreatUpdate  # named from here by its callers
from pfp_service.wire.messages import MAX_SNAPSHOT_ITEMS, fit_text
from pfp_service.world import dispersion, heights, kinds, missions, slopes, steering, team_route, wave
from pfp_service.world import events as ev
from pfp_service.world.bulkheads import Bulkheads
from pfp_service.world.cluster import Cluster
from pfp_service.world.events import *  # noqa: F403 -- the world's inputs and outputs, named from here too
from pfp_service.world.events import Batch, Input, Outputs, UnitView, WorldSettings
from pfp_service.world.limits import Limits
from pfp_service.world.liveness import UNIT_TIMERS, Liveness
from pfp_service.world.lookahead import Owed, owed_share
from pfp_service.world.neighbours import Reports
from pfp_service.world.snapshot import page as snapshot_page
from pfp_service.world.team_book import TeamBook
from pfp_service.world.terrain import link_sight
from pfp_service.world.threat_puts import ThreatPuts
from pfp_service.world.timers import Timers
from pfp_service.world.units import Answer, UnitRecord
from pfp_service.world.wave import POINTS_CHUNK, WAVE_CHUNK, WAVE_PER_TICK, Wave, split
from pfp_service.world.world_records import Records
from pfp_service.world.zone_puts import ZonePuts

__all__ = ["World", *ev.__all__]

K = keys.KeyKind
# A contingency that re-directs more guided units than this sends their directions first, and their
# look-ahead points in the next ``apply`` (``World.wave_pending``; figures: docs/operations.md, "The wave first")
WAVE_FIRST = 64
# ... and those points (and their jobs) follow at most this many units an ``apply``, the rest owed on
OWED_PER_TICK = 64
# the key a timer's fault is rejected on (a unit's goal for the rest)
TIMER_KEYS = {"expire": K.THREAT, "sight": K.THREAT, "zone_expire": K.ZONE, "peer": K.ALIVE_PLANNER}


class World:
    """Units, goals and threats of one mission, and the steppers that guide the units."""

    def __init__(self, settings: WorldSettings | None = None) -> None:
        self.settings = s = settings or WorldSettings()
        self._rec = Records(s.planner.intensity, s.terrain)
        self.records = self._rec  # read, never written, by others: a team preview's seed (``team_preview``)
        self._book = self._rec.book  # the units' one writer (``units.Units``): every step of a unit's phase
        self._units = self._rec.units
        self._threats = self._rec.threats
        self._timers = Timers()
        self._live = Liveness(s, self._book, self._timers)
        self._cluster = Cluster(s, self._book, self._timers, self._start, self._direct)
        self.limits = Limits()
        bulk = Bulkheads(s, self._units, self._book, self.limits)  # a failure is its input's or unit's alone
        self._key, self._fault, self._unit_fault, self._reject = (
            bulk.key,
            bulk.fault,
            bulk.unit_fault,
            bulk.reject,
        )
        self._puts = ThreatPuts(s, self._rec, self._timers, self.limits, self._reject)  # threats' inputs
        self._zones = ZonePuts(s, self._rec, self._timers, self.limits, self._reject)  # zones' inputs
        self._reports = Reports(self._book.seen)  # the units reported (``Reports``): looked at alone
        self.teams = TeamBook(link_sight(s.terrain), self._book.seen, self._reports)  # a link's range, sight
        self._route = team_route.RouteKeys(self._rec, self.teams, s.terrain)  # a lead's, for its followers
        self._disp = dispersion.Dispersion(  # off unless enabled; a team's separation_m among its members
            s.dispersion, self._units, self._book.yielded, self.teams.dispersed, self.teams.where
        )
        self._owed: list[Owed] = []  # a wave's units sent without look-ahead points (``lookahead.Owed``)
        self._wave = Wave()  # a wave's units owed their very direction (``wave``): before any points
        self._now = 0.0  # the last ``apply``'s: when a wave's points are owed, they are due at once

    # -- queries (read-only) ------------------------------------------------------
    @property
    def field(self) -> ThreatField:
        return self._rec.field

    def counts(self) -> dict[str, int]:
        """Figures for the status reply (O(1) but ``units_owned``)."""
        return {**self._rec.counts(), **self.limits.counts(), **self._live.counts()}

    def view(self, unit_id: str) -> UnitView:
        """A detached copy of one unit and the threats in force (a preview runs on it, off the loop)."""
        rec, s = self._units.get(unit_id), self.settings
        threats = self.field.threats  # the same tuple while the field stands: a preview service can cache it
        key = self._route(rec)  # its zones (the same set while they stand) and the height it is seen at
        zones, tall = self._rec.zone_set_for(*key[:3]), key[3]
        if rec is None:
            return UnitView(unit_id, None, None, None, None, threats, s, zones=zones)
        stepper = copy.deepcopy(rec.stepper) if rec.stepper is not None else None
        where = (rec.position, rec.goal, rec.origin)
        return UnitView(unit_id, *where, stepper, threats, s, rec.last_vector, zones, tall, rec.mobility)

    def snapshot(
        self,
        now: float,
        limit: int = MAX_SNAPSHOT_ITEMS,
        units_from: str | None = None,
        threats_from: str | None = None,
        max_bytes: int | None = None,
        threats_limit: int | None = None,
        zones_from: str | None = None,
        zones_limit: int | None = None,
        writes_from: str | None = None,
        writes_limit: int | None = None,
    ) -> WorldSnapshot:
        """One page of what the planner holds, for the world queryable (``snapshot.page``); ``writes``: ``kinds.held``."""
        s, page = self.settings, (limit, units_from, threats_from, max_bytes, threats_limit, zones_from)
        listed = (self.teams.summaries(self._units), kinds.held(self), writes_from, writes_limit)
        return snapshot_page(self._rec, now, s.mission, s.planner_id, *page, zones_limit, *listed)

    def next_deadline(self) -> float | None:
        """When the world next needs an ``apply`` (a ``Tick`` will do), on the clock ``apply`` is given.

        In the manner of aioquic's ``get_timer()``: the earliest of its timers
        (staleness, token debounce, push re-sends, forgetting, expiry, a peer
        gone), or at once -- the ``now`` of the last ``apply`` -- while it
        ``wave_pending``.  ``None``: nothing is due until an input
        comes.  A timer may find nothing left to do when due (a unit heard
        since): it is a reminder, not a verdict (``timers``).
        """
        if self._owed or self._wave:
            return self._now
        return self._timers.next_due()

    def wave_pending(self) -> bool:
        """Whether a wave's directions (``wave.WAVE_PER_TICK`` an ``apply``), then its look-ahead points
        (``OWED_PER_TICK``), wait for the next ``apply`` (a ``Tick`` will do): call it soon."""
        return bool(self._owed) or bool(self._wave)

    def directions_owed(self) -> bool:
        """Whether units a change reached still wait for their first direction (not only for their points)."""
        return bool(self._wave)

    def owns(self, unit_id: str) -> bool:
        """Whether this planner guides ``unit_id`` (``Ownership.owns``)."""
        return self._cluster.own.owns(unit_id)

    def shards(self) -> frozenset[int]:
        """The state shards this planner owns (``Ownership.shards``): the node subscribes to these."""
        return self._cluster.own.shards()

    def preview(self, unit_id: str) -> UnitView | None:
        """What a preview of ``unit_id`` runs on; ``None``: another planner answers it (its owner, once)."""
        return self.view(unit_id) if self.owns(unit_id) else None

    # -- the one way in -----------------------------------------------------------
    def apply(
        self,
        inputs: list[Input] | tuple[Input, ...],
        now: float,
        clock: Callable[[], float] | None = None,
        share: bool = True,
    ) -> Outputs:
        """Apply a batch of inputs at ``now``; return what must go out.

        ``clock``: the driver's (the node's loop passes its thread's CPU clock): a wave's share is then
        steered while the apply's budget lasts (``wave.Budget``), not ``WAVE_PER_TICK`` units; the world
        reads it for that alone.  ``share=False`` (timed only): none of an owed wave is drawn, so the
        batch's directions go out before it (the node then applies nothing but the share).
        Its driver holds the cyclic collector off around the call (``gcpause``: the node's
        loop until the directions are out), not the world, which imports no collector.
        """
        b, budget = Batch(now), wave.Budget(clock) if clock is not None else None
        self._now = now
        for inp in inputs:
            try:
                self._apply_one(inp, b)
            except Exception as exc:  # the bulkhead: this input alone fails
                self._fault(b, *kinds.blame(inp, self.settings.mission), exc)
        if b.changes or b.zones:
            self._world_changed(b, WAVE_PER_TICK if budget is None else WAVE_CHUNK)
        first = len(b.out.directions)  # before: pushes sent again by the timers
        self._directions(b, budget, share)
        pushed = b.out.directions[first:]
        if b.wave:  # a wave's directions are pushes once they carry their points, in the next apply
            pushed = [d for d in pushed if d.unit not in b.wave]
        self._live.pushed(pushed, now)
        if b.changes or b.zones:
            zones = [(z, c) for z, c, _ in b.zones if c]
            p, later = self.settings.planner_id, self._wave.ids()  # a wave's units owed: named now, told soon
            b.out.events.append(steering.replan(p, b.changes, b.out.directions, zones, later))
        slopes.said(self._rec, b, self.settings.planner_id)
        b.out.cancelled, self._book.superseded = self._book.superseded, []
        return b.out

    def _apply_one(self, inp: Input, b: Batch) -> None:
        match inp:
            case ev.StateReported(unit, state):
                self._state(unit, state, b)
            case ev.GoalSet(unit, goal):
                rec = self._units.get(unit)  # a peer's mission for this very goal may have come first: kept
                keep = rec.shared if rec and not rec.owned and rec.shared and rec.shared[0] == goal else None
                self._adopt(unit, goal, keep, b)
            case ev.GoalCancelled(unit):
                rec = self._units.get(unit)
                if rec is not None and rec.goal is not None:
                    self._rec.drop_mission(rec, GOAL_CANCELLED)
                    self._direct(rec, b)
            case ev.ThreatPut(tid, update):
                self._puts.put(tid, update, b)
            case ev.ThreatRemoved(tid):
                self._puts.gone(self._rec.remove_threat(tid), tid, "removed", b)
            case ev.SightLanded():
                self._puts.landed(inp, b)
            case ev.SlopeLanded():
                slopes.land(self._rec, inp, b, self.settings.planner_id)
            case ev.ZonePut(zid, update):
                self._zones.put(zid, update, b)
            case ev.ZoneRemoved(zid):
                self._zones.gone(self._rec.remove_zone(zid), zid, "removed", b)
            case ev.TeamPut() | ev.TeamRemoved():
                self._team(inp, b)
            case ev.TokenChanged(unit, alive):
                rec = self._units.get(unit)
                if rec is not None:  # a token alone makes no unit: only a report does
                    self._live.token(rec, alive, b.now)
            case ev.InputRejected(key, error, kind):
                self._reject(key, error, b, kind)
            case ev.Deliberated():
                self._deliberated(inp, b)
            case ev.MissionRestored(unit, goal, origin, params):
                self._adopt(unit, goal, (goal, origin, params), b, restored=True)
            case ev.MissionShared(unit, mission):
                rec = self._unit(unit, b, K.UNIT_MISSION)
                if rec is not None and not rec.owned:  # our own missions come back to us too: ours stands
                    self._rec.share(rec, mission)
            case ev.PeerPlanner():
                self._cluster.peer(inp, b)
            case ev.PeerTerrain():
                self._cluster.terrain(inp, b)
            case ev.Tick(t, shed):
                self.limits.overload += shed
                self._run_timers(t, b)
            case _:  # a kind in the table without its case here: rejected on its key, never dropped unsaid
                raise TypeError(f"no handler for {type(inp).__name__} in World._apply_one")

    # -- inputs ---------------------------------------------------------------------
    def _unit(self, unit_id: str, b: Batch, kind: keys.KeyKind, reported: bool = False) -> UnitRecord | None:
        """The unit's record, made at its first input (stale then, unless ``reported``)."""
        rec = self._units.get(unit_id)
        if rec is None:
            s = self.settings
            if len(self._units) >= s.max_units:
                self.limits.overload += 1
                err = InputError("$", f"planner at max_units ({s.max_units})")
                self._reject(keys.KeyOf(kind, s.mission).key(unit_id), err, b, kind)
                return None
            rec = self._book.add(unit_id, self.owns(unit_id), b.now, reported)
            self._live.made(rec, b.now)
        return rec

    def _direct(self, rec: UnitRecord, b: Batch) -> None:
        """The unit is to get a fresh direction in this batch, if it has reported and is not stale."""
        if rec.position is not None and not rec.stale:
            b.dirty.add(rec.id)

    def _state(self, unit_id: str, state: UnitState, b: Batch) -> None:
        rec = self._unit(unit_id, b, K.UNIT_STATE, reported=True)
        if rec is None:
            return
        self._live.reported(rec, state, b.now)
        self._reports.note(rec)  # taken: the leads' tracks and dispersion's index look at it (``Reports``)
        if rec.owned:  # else another planner guides it; its report keeps it fresh here too
            if rec.goal is not None and rec.stepper is None:
                self._start(rec, b)
            b.dirty.add(unit_id)

    def _adopt(
        self, unit_id: str, goal: Goal, shared: missions.Shared | None, b: Batch, restored: bool = False
    ) -> None:
        """A goal set (keeping ``shared`` if given), or a mission restored: a new epoch, started if owned."""
        rec = self._unit(unit_id, b, K.UNIT_GOAL)
        if rec is None:
            return
        self._book.set_goal(rec, goal, shared)
        if restored and rec.owned:
            self._start(rec, b, record=False)
        elif rec.position is not None and rec.owned:
            self._start(rec, b)
            self._direct(rec, b)

    def _team(self, inp: ev.TeamPut | ev.TeamRemoved, b: Batch) -> None:
        """A team put (refused on its key when it clashes with the teams in force) or dissolved: its units re-told."""
        err, units = self.teams.apply(inp)
        if err is not None:
            self._reject(self._key(K.TEAM, inp.team), err, b, K.TEAM)
        for rec in filter(None, map(self._units.get, units)):
            if rec.stepper is not None:  # a lead's route is priced for its followers (``team_route``)
                self._book.rejudge(rec)
            self._direct(rec, b)
        for unit, goal in self.teams.placed(self._units):  # a team goal: each member's place, its goal
            self._adopt(unit, goal, None, b)

    def _deliberated(self, done: ev.Deliberated, b: Batch) -> None:
        rec = self._units.get(done.unit)
        answer = self._book.deliberated(rec, done) if rec is not None else Answer.IGNORED
        if answer is Answer.FAILED and rec is not None and done.error is not None:  # as a fault here would
            self._unit_fault(b, rec, RuntimeError(done.error[1]), done.error)
        elif answer is Answer.TELL and rec is not None:
            self._direct(rec, b)  # a route or a verdict: told at once, not at its next report

    # -- timers ---------------------------------------------------------------------
    def _run_timers(self, now: float, b: Batch) -> None:
        for kind, ident in self._timers.due(now):
            try:
                if kind == "peer":  # a peer's token gone for the whole debounce: its units move
                    self._cluster.settle(ident, now, b)
                elif kind == "expire":
                    self._puts.gone(self._rec.expire(ident, now), ident, "expired", b)
                elif kind == "sight":  # a threat's window not landed in time: in force blind
                    self._puts.give_up(ident, b)
                elif kind == "zone_expire":
                    self._zones.gone(self._rec.expire_zone(ident, now), ident, "expired", b)
                elif kind in UNIT_TIMERS and (rec := self._units.get(ident)) is not None:
                    self._live.due(kind, rec, now, b.out)
            except Exception as exc:  # the bulkhead: this timer alone fails
                on = TIMER_KEYS.get(kind, K.UNIT_GOAL)
                self._fault(b, self._key(on, ident), ident if on is K.UNIT_GOAL else None, on, exc)

    # -- planning -------------------------------------------------------------------
    def _start(self, rec: UnitRecord, b: Batch, record: bool = True) -> None:
        """Fix the unit's mission and give it a stepper (``missions.start``); a mission refused drops the goal."""
        fld = self._rec.field_for(*self._route(rec))  # builds the stats with it
        started = missions.start(rec, self.settings, fld, self._rec.stats)
        if isinstance(started, InputError):
            self._reject(self._key(K.UNIT_GOAL, rec.id), started, b, K.UNIT_GOAL)
            self._book.drop_mission(rec, fit_text(f"goal refused: {started.reason}"))
            return
        self._book.started(rec, started[0])
        if record:
            b.out.missions.append(started[1])

    def _world_changed(self, b: Batch, share: int) -> None:
        """The threats or zones changed: re-judge and re-direct the units the change can reach (``reach.reached``; over terrain judged off the loop, ``wave.reached_with``).

        A unit out of reach keeps its direction (one escaping or deliberating out of its wider reach, its
        job too): a contingency costs what it touches.  A wave's units past ``share`` are owed (``wave``).
        """
        guided, wide = wave.guided(self._units)
        tall = [self._route.height(r) for r in guided]  # each seen at its own class's height (``heights``)
        zones, intensity = [z[2] for z in b.zones], self.settings.planner.intensity
        reached = heights.reached_seen(
            guided, tall, b.touched, intensity, zones, self._rec.sight, wide, b.judged
        )
        rejudge, hits = self._book.rejudge, []  # per unit of a wave: looked up once
        for rec, hit in zip(guided, reached):
            try:
                if hit:
                    rejudge(rec)
                    hits.append(rec)
            except Exception as exc:
                self._unit_fault(b, rec, exc)
        now, later = split(hits, b.touched, [z[2] for z in b.zones], b.dirty, share)
        self._wave.owe(later)  # told in the next applies, a share each (``wave``)
        b.shared = len(now) if later else 0
        b.dirty.update(r.id for r in now if r.position is not None and not r.stale)  # as ``_direct``

    def _directions(self, b: Batch, budget: wave.Budget | None = None, share: bool = True) -> None:
        """A fresh direction for each live unit of the batch, and a wave's share; one whose step fails loses its goal.
        Untimed (no ``clock``) the share is the next ``WAVE_PER_TICK`` owed, steered with the batch; timed, the
        batch's own units go first (their directions first out), then the share while the budget lasts (``_shares``)."""
        out, timed = b.out, budget is not None
        drawing = not (
            timed or b.changes or b.zones
        )  # untimed, none in the change's own apply: ``split`` drew
        drew = self._wave.take(b.dirty, self._units, WAVE_PER_TICK) if drawing else []
        b.dirty.update(drew)  # a wave's next share, owed since its change
        live = [r for uid in sorted(b.dirty) if (r := self._units.get(uid)) is not None and r.live()]
        out.directions += [self._no_goal(r) for r in live if r.stepper is None]
        guided = [r for r in live if r.stepper is not None]
        limit = (
            0 if self._wave or timed else OWED_PER_TICK
        )  # a wave's points: once its directions are all out
        later, self._owed = owed_share(self._owed, b.dirty, self._units, limit)
        first, sent, failed = len(out.directions), list[tuple[float, float] | None](), steering.Failed()
        big = (b.changes or b.zones) and (len(guided) > WAVE_FIRST or self._wave)  # a wave, large or owed
        if guided or later:
            self._steer(b, guided, later, bool(drew or big), sent, failed)
        if budget is not None and share:  # ``share=False``: the driver applies the share on its own
            self._shares(b, budget, sent, failed)
        if len(out.directions) == first and not failed:  # none steered: the roles are not judged
            return
        told, kept_clear = out.directions[first:], self._rec.step_zones(self._route)  # roles keep clear
        out.directions[first:] = self.teams.judge(told, self._units, zones_of=kept_clear, now=b.now)
        if self.settings.origin is not None and sent:  # lat/lon for the whole tick in one conversion
            out.directions[first:] = steering.geodetic(out.directions[first:], self.settings.origin, sent)
        out.events += self._disp.right_of_way(out.directions, first, b.now)  # yield: hold, or back off
        # a unit whose step failed lost its goal: told so, once the rest are out
        out.directions += [self._no_goal(r) for r, _ in failed if r.id in self._units and r.live()]

    def _shares(
        self, b: Batch, budget: wave.Budget, sent: list[tuple[float, float] | None], failed: steering.Failed
    ) -> None:
        """A timed apply's share of a wave: its next units, ``WAVE_CHUNK`` at a time while ``budget`` lasts (one chunk at
        least, ``WAVE_PER_TICK`` at most; ``split`` drew one in the change's own apply); once every direction is out
        and none went out in this apply, their points ``POINTS_CHUNK`` at a time while its points' budget lasts (at most
        ``OWED_PER_TICK``)."""
        while self._wave and b.shared < WAVE_PER_TICK and not (b.shared and budget.spent()):
            drew = self._wave.take(b.dirty, self._units, WAVE_CHUNK)
            b.dirty.update(drew)
            b.shared += len(drew) or WAVE_PER_TICK
            self._steer(b, [self._units[u] for u in drew], [], True, sent, failed)
        if b.shared:  # no points in an apply that told a wave's directions: those go out first
            return
        drawn = 0
        while self._owed and drawn < OWED_PER_TICK and not (drawn and budget.points_spent()):
            later, self._owed = owed_share(self._owed, b.dirty, self._units, POINTS_CHUNK)
            drawn += len(later) or OWED_PER_TICK
            self._steer(b, [], later, False, sent, failed)

    def _steer(self, b: Batch, guided: list[UnitRecord], later: list[tuple[UnitRecord, Advice]], first: bool,
               sent: list[tuple[float, float] | None], failed: steering.Failed) -> None:  # fmt: skip
        """Steer ``guided`` (``first``: a wave's, their directions now and their points owed) and compute the points of
        ``later``; each direction appended to the batch's, its unit's position to ``sent``, each failure to ``failed``."""
        p, out = self.settings.planner_id, b.out
        field_for, n, cull_for = self._rec.field_for, self.settings.lookahead, self._rec.cull_for
        steered: steering.Steered = []
        lost_all: steering.Failed = []
        wave_first = n > 0 and first
        groups = self._route.groups(guided, later)  # a field per slope limit, corridor and height
        for key, (group, owed) in groups.items():
            fld, cull = field_for(*key), cull_for(key[3])
            lost: steering.Failed = []
            if group and wave_first:  # the wave first
                advised, lost = steering.advise(group, fld, cull, self._disp)
                steered += [(r, a, []) for r, a in advised]
                self._owed += [
                    (r, a, st, st.version, r.seq) for r, a in advised if (st := r.stepper) is not None
                ]
                b.wave |= {r.id for r, _ in advised}
            elif group:
                done, lost = steering.steer(group, fld, cull, n, self._disp)
                steered += done
            lost_all += lost
            if owed:
                tracked, lost = steering.ahead(owed, fld, cull, n)
                steered += tracked
                lost_all += lost
        for rec, exc in lost_all:
            self._unit_fault(b, rec, exc)
        failed += lost_all
        direction, wave, events, directions = steering.direction, b.wave, out.events, out.directions
        keep = self._book.steered
        for rec, adv, points in steered:  # per unit of a wave: names looked up once, above
            try:
                job = rec.job
                d, event, verdict = direction(rec, adv, points, p, job is not None)
                keep(rec, verdict)
                if job is None and rec.id not in wave:  # a wave's jobs are asked with its points
                    st = rec.stepper
                    if st is not None and st.pending is not None:
                        self._deliberate(rec, field_for(*self._route(rec)), b)
            except Exception as exc:
                self._unit_fault(b, rec, exc)
                failed.append((rec, exc))
                continue
            if event is not None:
                events.append(event)
            directions.append(d)
            sent.append(rec.position)

    def _no_goal(self, rec: UnitRecord) -> Direction:
        self._book.steered(rec, steering.NO_GOAL._replace(reason=rec.goal_gone))
        return steering.no_goal(rec, self.settings.planner_id)

    def _deliberate(self, rec: UnitRecord, fld: ThreatField, b: Batch) -> None:
        assert rec.stepper is not None and rec.stepper.pending is not None
        kind, deadline = rec.stepper.pending.kind, b.now + self.settings.deliberation_budget_s
        job = ev.Job(rec.id, rec.token(), kind, rec.stepper, fld, deadline, live=True)  # Job.detach copies
        self._book.asked(rec, job)
        b.out.jobs.append(job)
