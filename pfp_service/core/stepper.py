"""The per-unit stepper: given where a unit is, say which way it should go next.

One stepper serves two drivers.  ``plan()`` moves a simulated unit along the
directions it returns (a preview); the live daemon feeds it the positions the
unit reports.  Its state is the unit's goal, its mode and a short recent track,
which is what trap detection needs.  It never reads a clock and never moves the
unit itself.

The rules -- arrival, bounds, the direction, the final approach onto the
goal and trap detection -- are ``steprule.judge``, the one compiled rule every
driver shares; the stepper keeps its unit's ``steprule.unit`` (goal, rules and
trap watch) and says what each verdict means.  Trap detection (plain descent
has no memory, so this is the only guard):

* *stall*: over the last ``trap_window`` advisories the unit moved less than
  ``0.2 * trap_window * step`` net, i.e. it is oscillating about a point;
* *no progress*: the best distance to goal has not improved by a tolerance in
  ``progress_window`` advisories (a slow creep into a basin or an orbit).

Either one ends plain descent with ``trapped`` and the reason, rather than
running on silently to ``max_iter``.  The verdict stands while the unit stays
where it was trapped; a unit reported more than ``trap_window * step`` away
from that point (a person walked it out) is guided again, judged afresh.
Plain descent ends -- unless ``escape`` is set: then the
verdict goes to the unit's ``escape.Escaper``, which either commits to a way
out (status ``escaping`` while the unit follows it, then plain descent again)
or confirms ``trapped`` with every strategy's reason.  Descent pays nothing
for this until a trap: the escape state is created at the first one.

Look-ahead (``escape: auto`` only): at the first advisory after the goal is
set, and after each ``world_changed``, the stepper simulates its own plain
descent from the reported position (``foresight``, one compiled loop).  If
that simulation is trapped or leaves the bounds, the unit commits to the
``global`` route round the trap at once (status ``escaping``) instead of
walking in and back out.  Otherwise, and on every other advisory, nothing
extra runs: a unit whose descent is foreseen to arrive moves exactly as
under ``escape: none``.

Deliberation.  The look-ahead and the escape search are the stepper's only
unbounded work.  With ``defer`` set (the live daemon), the stepper does not
run them inline: it records a ``Need`` and keeps answering plain steepest
descent (``Advice.deliberating``).  A driver runs ``deliberate()`` on a
detached copy, off the planning loop, and hands the copy back to
``adopt()``.  Without ``defer`` (``plan()``, previews) the same work runs
inline at the same advisory, so a preview shows the route as the unit will
follow it once the deliberation has landed.

Ghosts.  ``ghost()`` is a cheap copy that predicts (the direction
look-ahead points): it follows a committed escape, but a trap ends it and
it never deliberates.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from pfp_service.core import foresight, steprule, tracking, zones
from pfp_service.core.advice import Advice, Need, StepStatus
from pfp_service.core.escape import Escaper
from pfp_service.core.metrics import LAMBDA
from pfp_service.core.params import Resolved
from pfp_service.core.route import NO_LIMIT, EscapeRun, descent_route
from pfp_service.core.threat import ThreatField
from pfp_service.core.tracking import Route

__all__ = ["Advice", "Bounds", "Need", "StepStatus", "Stepper"]

Bounds = tuple[tuple[float, float], tuple[float, float]]


_tuple = tuple.__new__  # a NamedTuple from all its fields, in order, without its Python-level __new__


class Stepper:
    """Steepest descent on ``f = sum_j w_j t_j + delta ||goal - x||^2 / ||goal - x0||^2``.

    Args:
        origin: ``x0``, where the unit was when the goal was assigned.
        goal: the target position.
        params: resolved planner parameters (``core.params.resolve``).
        bounds: optional ``((xmin, ymin), (xmax, ymax))``; leaving them ends the run.
        unit_key: seeds this unit's random escapes (with ``params.seed``); give
            each live unit its own, and its preview the same one.
    """

    __slots__ = (
        "_corridor",
        "_ends",
        "_escaper",
        "_foresee",
        "_ghost",
        "_lead",
        "_run",
        "_terminal",
        "_trap_at",
        "_traps",
        "_unit",
        "advisories",
        "bounds",
        "defer",
        "goal",
        "goal_gain",
        "origin",
        "params",
        "pending",
        "speed_mps",
        "tracking",
        "unit_key",
        "version",
    )

    def __init__(
        self,
        origin: tuple[float, float],
        goal: tuple[float, float],
        params: Resolved,
        bounds: Bounds | None = None,
        unit_key: int = 0,
    ) -> None:
        self.goal = (float(goal[0]), float(goal[1]))
        self.origin = (float(origin[0]), float(origin[1]))
        self.params = params
        self.bounds = bounds
        d0sq = (self.goal[0] - self.origin[0]) ** 2 + (self.goal[1] - self.origin[1]) ** 2
        self.goal_gain = params.delta / d0sq if d0sq > 0 else 0.0
        self.advisories = 0
        # the goal, the rules and the trap watch, as ``steprule.judge`` reads them
        self._unit = steprule.unit(
            self.goal,
            self.goal_gain,
            params.tolerance,
            params.step,
            bounds,
            params.trap_window,
            params.progress_window,
        )
        self._terminal: Advice | None = None
        self._trap_at: tuple[float, float] | None = None  # where the standing trapped verdict was given
        self.unit_key = unit_key
        self._escaper: Escaper | None = None
        self._run: EscapeRun | None = None
        self._traps = 0
        self._foresee = params.escape == "auto"  # look ahead at the next advisory
        self._ghost = False
        self.defer = False  # record deliberation as ``pending`` instead of running it inline
        self.pending: Need | None = None
        self.version = 0  # bumped by every world change: a deliberation is for one version
        self.tracking = False  # a live unit's: traps from the field, routes tracked (``track``)
        self.speed_mps = 0.0  # the unit's speed, as the driver last knew it (``pace``)
        self._lead = tracking.LEAD_STEPS  # its pursuit point's lead, in route points (``pace``)
        self._corridor = tracking.corridor(params.step)  # off its route by more: chosen again
        self._ends = ""  # a tracked route that ends where descent is foreseen trapped: why

    def __deepcopy__(self, memo: dict[int, object]) -> Stepper:
        """A detached copy (previews, deliberation): shares the immutable parts, copies the state."""
        new = Stepper.__new__(Stepper)
        for name in Stepper.__slots__:  # numbers, tuples, flags and the parameters: immutable, shared
            setattr(new, name, getattr(self, name))
        new._unit = self._unit.copy()
        if self._escaper is not None:
            new._escaper = copy.deepcopy(self._escaper, memo)
        if self._run is not None:  # its path is never changed, only its cursor: shared
            new._run = copy.copy(self._run)
        return new

    def ghost(self) -> Stepper:
        """A cheap predicting copy: follows a committed escape, stops at a trap, never deliberates."""
        new = Stepper.__new__(Stepper)
        for name in ("params", "bounds", "goal", "origin", "goal_gain", "unit_key", "advisories"):
            setattr(new, name, getattr(self, name))
        new._unit = self._unit.copy()
        new._terminal, new._trap_at = self._terminal, self._trap_at
        new._escaper, new._traps = None, self._traps
        new._run = copy.copy(self._run)  # the route is shared; only its cursor moves
        new._foresee = False
        new._ghost = True
        new.tracking = False
        new.speed_mps = self.speed_mps
        new._lead = self._lead
        new._corridor = self._corridor
        new._ends = ""
        new.defer = False
        new.pending = None
        new.version = self.version
        return new

    def track(self) -> None:
        """Guide a live unit, whatever it does between two reports (``core.tracking``).

        Its reports are never judged as steps: the trap watch is off, a trap
        is what the look-ahead foresees from where the unit is (under every
        ``escape``), and the route it foresees is tracked.
        """
        p = self.params
        self.tracking = True
        self._unit = steprule.unit(self.goal, self.goal_gain, p.tolerance, p.step, self.bounds, watch=False)
        self._foresee = not self._ghost

    def pace(self, speed_mps: float) -> None:
        """The unit's speed over the ground, as last reported or measured: its pursuit point's lead.

        The lead (in route points) changes only when the speed changes it by
        more than a point and a quarter, so a measured speed's jitter never
        moves the pursuit point between two reports.
        """
        if speed_mps == self.speed_mps:  # the same speed, report after report: nothing to do
            return
        self.speed_mps = speed_mps if math.isfinite(speed_mps) and speed_mps > 0.0 else 0.0
        lead = tracking.lead_points(self.params.step, self.speed_mps)
        if abs(lead - self._lead) > max(1.0, 0.25 * self._lead):
            self._lead = lead

    def deliberate(self, field: ThreatField) -> None:
        """Run the pending deliberation inline (on a detached copy, off the planning loop)."""
        need = self.pending
        self.pending = None
        self.defer = False
        if need is None:
            return
        if need.kind == "foresee":
            self._look_ahead(field, need.x, need.y)
            return
        self._traps += 1
        if self._escaper is None:
            self._escaper = Escaper(self.params, self.goal, self.goal_gain, self.bounds, self.unit_key)
        run, why = self._escaper.begin(field, need.x, need.y, need.reason)
        if run is None:
            level = field.level_grad_at(need.x, need.y)[0]
            dist = math.hypot(self.goal[0] - need.x, self.goal[1] - need.y)
            self._end(StepStatus.TRAPPED, level, dist, why, (need.x, need.y))
        else:
            self._run = run

    def adopt(self, done: Stepper) -> bool:
        """Take the outcome of ``done.deliberate()`` (a copy of this stepper at the same version).

        Returns:
            True when it changes what the unit is told (a route to follow, or a
            trapped verdict); a foreseen arrival changes nothing.
        """
        self.pending = None
        self._escaper = done._escaper
        self._traps = done._traps
        self._run = done._run
        self._ends = done._ends
        if done._terminal is not None and done._terminal.status is StepStatus.TRAPPED:
            self._terminal, self._trap_at = done._terminal, done._trap_at
        changed = self._run is not None or self._terminal is not None
        if self._run is not None:  # a route to follow: descent is judged afresh after it
            steprule.reset_watch(self._unit)
        return changed

    @property
    def traps(self) -> int:
        """How many times plain descent was trapped for this goal (or foreseen to be, and went round)."""
        return self._traps

    @property
    def escape_steps(self) -> int:
        """Advisories given while escaping (status ``escaping``)."""
        return self._escaper.escape_steps if self._escaper is not None else 0

    @property
    def escapes(self) -> list[str]:
        """The strategy of each escape committed to, in order."""
        return list(self._escaper.log) if self._escaper is not None else []

    def world_changed(self) -> None:
        """Threats appeared, moved or vanished: judge progress afresh from here."""
        steprule.reset_watch(self._unit)
        self._run = None  # judged under the old field
        self._ends = ""
        self._foresee = (self.params.escape == "auto" or self.tracking) and not self._ghost
        self.pending = None  # asked under the old field
        self.version += 1
        if self._escaper is not None:
            self._escaper.forget_sites()
        if self._terminal is not None and self._terminal.status is StepStatus.TRAPPED:
            self._terminal = None
            self._trap_at = None

    def advise(self, field: ThreatField, x: float, y: float) -> Advice:
        """The next direction for a unit at ``(x, y)`` under ``field``."""
        if self._terminal is None and self._run is None and not self._foresee and not field.zones:
            return self._descend(field, x, y)  # plain descent: one call
        early = self.check(x, y)
        if early is not None:
            if early.status is StepStatus.TRAPPED:
                return early._replace(level=field.level_grad_at(x, y)[0])
            return early
        if field.zones:
            zoned = self._zoned(field, x, y)
            if zoned is not None:
                return zoned
        if self._foresee:
            if self.defer:
                self._foresee = False
                self.pending = Need("foresee", x, y)
            else:
                self._look_ahead(field, x, y)
        if self._run is not None:
            return self._escaping(field, x, y)
        return self._descend(field, x, y)

    def _descend(self, field: ThreatField, x: float, y: float) -> Advice:
        """Plain descent at ``(x, y)``: the gradient and the verdict in one compiled call."""
        if self.params.trap_window > steprule.RING_START:  # the ring may need to grow
            self._unit = steprule.roomy(self._unit)
        code, dx, dy, level, dist, move, tx, ty = steprule.descend(
            field.packed, *field.zones.packed(), self._unit, x, y
        )
        return self._judged(field, x, y, level, code, dx, dy, dist, move, tx, ty)

    def _zoned(self, field: ThreatField, x: float, y: float) -> Advice | None:
        """What keep-out zones decide before descent: a goal in a zone, or a unit in one.

        A goal in a zone is ``trapped`` ("the goal lies in zone Z"); a unit in a
        zone leaves it by the shortest way out first (an escape run, ``leave
        zone Z``), or is ``trapped`` when there is none.  ``None``: descend.
        """
        zones = field.zones
        goal_in = zones.zone_at(*self.goal)
        if goal_in:
            return self._walled(field, x, y, f"the goal lies in zone {goal_in}")
        if self._run is not None:
            return None
        here = zones.zone_at(x, y)
        if not here or (self._foresee and not self.defer):  # the look-ahead leaves first, then plans on
            return None
        if self._escaper is None:
            self._escaper = Escaper(self.params, self.goal, self.goal_gain, self.bounds, self.unit_key)
        run = self._escaper.leave_core(field, x, y)
        if run is None:
            return self._walled(
                field, x, y, f"inside zone {here}, with no straight way out that enters no other zone or core"
            )
        self._run = run
        return self._escaping(field, x, y)

    def _walled(self, field: ThreatField, x: float, y: float, reason: str) -> Advice:
        """``trapped`` by keep-out zones where the unit stands, for ``reason``."""
        self._traps += 1
        dist = math.hypot(self.goal[0] - x, self.goal[1] - y)
        return self._end(StepStatus.TRAPPED, field.level_grad_at(x, y)[0], dist, reason, (x, y))

    def check(self, x: float, y: float) -> Advice | None:
        """The part of ``advise`` that needs no field: arrival, bounds, a standing verdict.

        A standing ``trapped`` verdict comes back with this position's distance
        and the level it was given with (``advise`` fills in this position's);
        it is dropped, and ``None`` returned, once the unit is more than
        ``trap_window * step`` from where it was trapped.  A tracked unit's
        ``arrived`` stands likewise while it reports within the route corridor
        (``tracking.corridor``) of its goal: a fix that jitters past the
        tolerance once the unit has arrived is not a new trip.
        """
        code, _dx, _dy, dist, _move, _tx, _ty = steprule.judge(
            self._unit, x, y, 0.0, 0.0, 0.0, steprule.CHECK
        )
        if code != steprule.GO:
            status, reason = _VERDICTS[code]
            return self._end(status, 0.0, dist, reason)
        if self._terminal is None:
            return None
        if self._terminal.status is StepStatus.ARRIVED:  # a tracked unit that arrived: its fix may jitter out
            if dist <= tracking.corridor(self.params.step):
                return self._terminal._replace(distance=dist)
            self._terminal = None  # driven away from the goal: guided again
            return None
        if self._trap_at is not None:
            tx, ty = self._trap_at
            if math.hypot(x - tx, y - ty) > self.params.trap_window * self.params.step:
                self._terminal = None
                self._trap_at = None
                steprule.reset_watch(self._unit)
                return None
        return self._terminal._replace(distance=dist)

    def follow(
        self,
        x: float,
        y: float,
        fx: float,
        fy: float,
        level: float,
        norm: float,
        field: ThreatField | None = None,
    ) -> Advice:
        """``advise`` in plain descent, given the potential's gradient at ``(x, y)``: one ``steprule.judge`` call.

        Arrival and bounds are judged too (as ``check`` would).  ``advise_many``
        computes the gradients of many units in one kernel call and then calls
        this per unit.  ``field`` is needed only to escape a trap; without it a
        trap is final.
        """
        if self.params.trap_window > steprule.RING_START:  # the ring may need to grow
            self._unit = steprule.roomy(self._unit)
        if field is not None and field.zones:
            code, dx, dy, dist, move, tx, ty = steprule.judge_zoned(
                self._unit, *field.zones.packed(), x, y, fx, fy, norm
            )
        else:
            code, dx, dy, dist, move, tx, ty = steprule.judge(
                self._unit, x, y, fx, fy, norm, steprule.DESCENT
            )
        if code == steprule.GO:  # the common case, without a call (thousands of units a tick)
            self.advisories += 1
            return Advice(
                StepStatus.EN_ROUTE, dx, dy, level, dist, "", self.pending is not None, move, tx, ty
            )
        return self._judged(field, x, y, level, code, dx, dy, dist, move, tx, ty)

    def foresee_follow(
        self, x: float, y: float, fx: float, fy: float, level: float, norm: float, field: ThreatField
    ) -> Advice:
        """``advise`` of a deferring stepper that is to look ahead, with no verdict, route or zones: one judge call.

        What ``check`` then ``follow`` give (``advise_many``, after a change of
        the world): an arrival or bounds verdict ends it as ``check`` would,
        before the look-ahead is asked; else the look-ahead is asked
        (``pending``) and plain descent answers meanwhile.
        """
        if self.params.trap_window > steprule.RING_START:  # the ring may need to grow
            self._unit = steprule.roomy(self._unit)
        code, dx, dy, dist, move, tx, ty = steprule.judge(self._unit, x, y, fx, fy, norm, steprule.DESCENT)
        if (
            steprule.GO < code <= steprule.BAD_POSITION
        ):  # judged before the gradient and the watch, as ``check``
            status, reason = _VERDICTS[code]
            return self._end(status, 0.0, dist, reason)
        self._foresee = False
        self.pending = _tuple(Need, ("foresee", x, y, ""))  # per unit of a wave: a NamedTuple's __new__ is 2x
        if code == steprule.GO:
            self.advisories += 1
            return _tuple(
                Advice, (StepStatus.EN_ROUTE, dx, dy, level, dist, "", True, move, tx, ty, Route.NONE)
            )
        return self._judged(field, x, y, level, code, dx, dy, dist, move, tx, ty)

    def _judged(
        self,
        field: ThreatField | None,
        x: float,
        y: float,
        level: float,
        code: int,
        dx: float,
        dy: float,
        dist: float,
        move: float,
        tx: float,
        ty: float,
    ) -> Advice:
        """What ``steprule.judge``'s verdict on a descent advisory means for this unit."""
        if code == steprule.GO:
            self.advisories += 1
            return Advice(
                StepStatus.EN_ROUTE, dx, dy, level, dist, "", self.pending is not None, move, tx, ty
            )
        if code <= steprule.BAD_POSITION:  # arrival, bounds, position: judged before the gradient
            status, reason = _VERDICTS[code]
            return self._end(status, 0.0, dist, reason)
        if code == steprule.BAD_GRADIENT:
            return self._end(StepStatus.INVALID, level, dist, "gradient is not finite")
        if code == steprule.STATIONARY:
            return self._trapped(field, x, y, level, dist, "gradient vanishes (stationary point)")
        self.advisories += 1
        p = self.params
        if code == steprule.NO_PROGRESS:
            reason = f"no progress toward the goal in {p.progress_window} steps"
        else:
            reason = f"oscillating: moved under {0.2 * p.trap_window:g} steps net in {p.trap_window}"
        return self._trapped(field, x, y, level, dist, reason, dx, dy, move, tx, ty)

    # -- internals ----------------------------------------------------------
    def _look_ahead(self, field: ThreatField, x: float, y: float) -> None:
        """Simulate plain descent from here; go round now if it fails, or if going round is clearly cheaper.

        A unit inside a threat core first leaves it by the shortest way out
        (``Escaper.leave_core``), and the look-ahead starts where that ends.
        """
        self._foresee = False
        if self._escaper is None:
            self._escaper = Escaper(self.params, self.goal, self.goal_gain, self.bounds, self.unit_key)
        out = self._escaper.leave_core(field, x, y)
        ox, oy = (x, y) if out is None else out.end()
        sim = foresight.simulate(
            field, (ox, oy), self.goal, self.goal_gain, self.params, self.bounds, keep_path=self.tracking
        )
        auto = self.params.escape == "auto"
        run = None
        self._ends = ""
        if sim.outcome.fails and auto:
            run, _why = self._escaper.foresee(field, ox, oy, sim.outcome.value.replace("_", " "))
            if run is not None:  # else descend and meet the trap as usual
                self._traps += 1
        elif sim.outcome is foresight.Outcome.ARRIVES and auto:
            foreseen = sim.steps * sim.step + LAMBDA * sim.exposure
            run = self._escaper.cheaper_route(field, ox, oy, foreseen)
        if run is None and self.tracking and sim.path is not None:
            run, self._ends = descent_route(sim, self.goal)
        if out is not None:
            run = out.then(run)
        if run is not None:
            self._run = run

    def _trapped(
        self,
        field: ThreatField | None,
        x: float,
        y: float,
        level: float,
        dist: float,
        reason: str,
        dx: float = 0.0,
        dy: float = 0.0,
        move: float = math.inf,
        tx: float = math.nan,
        ty: float = math.nan,
    ) -> Advice:
        if self.params.escape == "none" or field is None or self._ghost:
            self._traps += 1
            return self._end(StepStatus.TRAPPED, level, dist, reason, (x, y))
        if self.defer:  # plain descent until the escape search lands
            if self.pending is None:
                self.pending = Need("escape", x, y, reason)
            return Advice(StepStatus.EN_ROUTE, dx, dy, level, dist, "", True, move, tx, ty)
        self._traps += 1
        if self._escaper is None:
            self._escaper = Escaper(self.params, self.goal, self.goal_gain, self.bounds, self.unit_key)
        run, why = self._escaper.begin(field, x, y, reason)
        if run is None:
            return self._end(StepStatus.TRAPPED, level, dist, why, (x, y))
        self._run = run
        return self._escaping(field, x, y)

    @property
    def escaping(self) -> bool:
        """Following a committed route other than the foreseen descent (which a change far off leaves be)."""
        return self._run is not None and self._run.route is not Route.DESCENT

    def route_left_m(self) -> float | None:
        """Metres still to drive along the committed route to the goal (past its end, straight on); ``None`` off one."""
        run = self._run
        if run is None or self._terminal is not None:
            return None
        left = run.left_m()
        if not run.to_goal:
            left += run.end_to(self.goal)
        return left

    def route_ahead(self, x: float, y: float, steps: int) -> list[tuple[float, float]] | None:
        """A ghost's next ``steps`` positions from ``(x, y)`` on the committed route (``EscapeRun.ahead``).

        ``None`` when there is no route, a standing verdict, or the route may
        end within those steps: then walk a ghost (``plan.walk_many``).
        """
        if self._run is None or self._terminal is not None:
            return None
        return self._run.ahead(self._unit, x, y, steps)

    def rules(self) -> np.ndarray:
        """This unit's goal and rules as ``steprule.judge`` reads them (a view, without the watch's ring)."""
        return self._unit[: steprule.RING]

    def step_along(self, x: float, y: float, dx: float, dy: float) -> tuple[float, float] | None:
        """Where one step along the heading ``(dx, dy)`` takes the unit at ``(x, y)`` (``steprule.judge``).

        ``None`` where it is not to move on (arrived, out of bounds, not finite).
        """
        code, _dx, _dy, _dist, _move, tx, ty = steprule.judge(self._unit, x, y, dx, dy, 1.0, steprule.HEADING)
        return (tx, ty) if code == steprule.GO else None

    def look_ahead_again(self) -> None:
        """A look-ahead asked for was dropped (its deadline passed): ask again at the next advisory."""
        self.pending = None
        self._foresee = (self.params.escape == "auto" or self.tracking) and not self._ghost

    def check_terminal(self) -> bool:
        """A standing verdict (trapped) that ``check`` would repeat, so a prediction must ask the stepper."""
        return self._terminal is not None

    def _escaping(
        self,
        field: ThreatField,
        x: float,
        y: float,
        level: float | None = None,
        again: bool = True,
        grad: tuple[float, float, float, float] | None = None,
    ) -> Advice:
        """Steer along the committed route; ``level`` is the threat level here when the caller has it.

        On a tracked descent the direction is descent's own (so a unit moved
        a step at a time is exactly where the preview's descent goes), and
        the route gives the corridor and the reach; ``grad`` is the batch's
        ``(fx, fy, level, norm)`` here, if it has it.  ``again``: a tracked
        route that ends here may be chosen again at once (not twice in one
        advice).
        """
        run = self._run
        assert run is not None
        if self.tracking:
            # among keep-out zones a route hugs their edges: the pursuit point stays two points on,
            # where a chord never cuts a zone's corner (``route_kernels._zone_heading``'s own rule)
            run.lead = tracking.LEAD_STEPS if field.zones else self._lead
            run.limit = NO_LIMIT  # a route is left by the corridor, never by counting reports
        stepped = run.steer(self._unit, x, y, field.zones)
        if self.tracking and run.off_m > self._corridor:
            stepped = None  # reported off its route: chosen again from here
            self._ends = ""
        if stepped is None:  # at the exit (or abandoned): plain descent takes over, judged afresh
            self._run = None
            steprule.reset_watch(self._unit)
            if self.tracking:
                return self._route_ended(field, x, y, level, again)
            return self._descend(field, x, y)
        if run.route is Route.DESCENT:
            return self._along_descent(field, x, y, grad)
        dx, dy, dist, move, tx, ty = stepped
        if self.tracking and not move > 1e-9 * self.params.step:  # the route's way on is walled off here
            self._run = None
            lv = field.level_grad_at(x, y)[0] if level is None else level
            return self._trapped(field, x, y, lv, dist, f"{run.name}: blocked by a keep-out zone")
        self.advisories += 1
        route = run.route
        if self._escaper is not None and route.escaping:  # a ghost has none: it only predicts
            self._escaper.escape_steps += 1
        if level is None:  # a ghost only predicts positions: the level it would report is never read
            level = 0.0 if self._ghost else field.level_grad_at(x, y)[0]
        reach = self._reach(field, x, y, dx, dy, dist, move, run.ahead_m) if self.tracking else move
        status, why = run.said()
        return Advice(status, dx, dy, level, dist, why, False, reach, tx, ty, route)

    def _along_descent(
        self, field: ThreatField, x: float, y: float, grad: tuple[float, float, float, float] | None
    ) -> Advice:
        """On a tracked descent route (``_run`` steered already): descent's advice, reaching on along the route."""
        adv = self._descend(field, x, y) if grad is None else self.follow(x, y, *grad, field)
        if adv.status is not StepStatus.EN_ROUTE or self._run is None:
            return adv
        reach = self._reach(field, x, y, adv.dx, adv.dy, adv.distance, adv.reach, self._run.ahead_m)
        return adv._replace(reach=reach, route=Route.DESCENT)

    def _reach(
        self,
        field: ThreatField,
        x: float,
        y: float,
        dx: float,
        dy: float,
        dist: float,
        move: float,
        ahead: float,
    ) -> float:
        """How far along ``(dx, dy)`` a tracked unit may go: to its pursuit point ``ahead`` metres off, not into a zone.

        A step cut short (of a zone) stays as judged.
        """
        if not move >= min(self.params.step, dist) * 0.999:
            return move
        reach = max(move, min(ahead, dist))
        if reach > move and field.zones:  # the way to the pursuit point may cut a zone's corner
            hit, zone = zones.segment_hit(*field.zones.packed(), x, y, x + dx * reach, y + dy * reach)
            if zone >= 0:
                reach = max(move, hit * reach - steprule.CLEAR_STEPS * self.params.step)
        return reach

    def _route_ended(
        self, field: ThreatField, x: float, y: float, level: float | None, again: bool
    ) -> Advice:
        """A tracked route ended short of the goal, or the unit left it: a trap foreseen there, or choose again."""
        ends, self._ends = self._ends, ""
        if ends:
            lv = field.level_grad_at(x, y)[0] if level is None else level
            return self._trapped(field, x, y, lv, math.hypot(self.goal[0] - x, self.goal[1] - y), ends)
        self._foresee = not self._ghost
        if self._foresee and not self.defer and again:
            self._look_ahead(field, x, y)
            if self._run is not None:
                return self._escaping(field, x, y, level, again=False)
        elif self._foresee:
            self._foresee = False
            self.pending = Need("foresee", x, y)
        return self._descend(field, x, y)

    def _end(
        self,
        status: StepStatus,
        level: float,
        dist: float,
        reason: str,
        at: tuple[float, float] | None = None,
    ) -> Advice:
        advice = Advice(status, 0.0, 0.0, level, dist, reason)
        if status is StepStatus.TRAPPED:
            self._terminal = advice
            self._trap_at = at
        elif status is StepStatus.ARRIVED and self.tracking:  # stands while the unit stays near the goal
            self._terminal = advice
            self._trap_at = None
        return advice


# what a verdict of ``steprule.judge`` found before any gradient means
_VERDICTS = {
    steprule.ARRIVED: (StepStatus.ARRIVED, "within tolerance"),
    steprule.OUT_OF_BOUNDS: (StepStatus.OUT_OF_BOUNDS, "left the mission bounds"),
    steprule.BAD_POSITION: (StepStatus.INVALID, "position is not finite"),
}
