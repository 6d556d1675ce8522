"""The per-unit stepper: given where a unit is, say which way it should go next.

One stepper serves two drivers.  ``plan()`` moves a simulated unit along the
directions it returns (a preview); the live daemon feeds it the positions the
unit reports.  Its state is the unit's goal, its mode and a short recent track,
which is what trap detection needs.  It never reads a clock and never moves the
unit itself.

The rules -- arrival, bounds, the direction, the final approach onto the
goal and trap detection -- are ``steprule.judge``, the one compiled rule every
driver shares; the stepper keeps its unit's ``steprule.unit`` (goal, rules and
trap watch) and says what each verdict means (``descent_stepper``, which also
says how a trap is detected).  A trap ends plain descent -- unless ``escape``
is set: then the verdict goes to the unit's ``escape.Escaper``, which either commits to a way
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
import weakref

import numpy as np

from pfp_service.core import foresight, steprule, tracking, zones
from pfp_service.core.advice import Advice, Need, StepStatus
from pfp_service.core.descent_stepper import Bounds, DescentStepper, _tuple
from pfp_service.core.escape import Escaper
from pfp_service.core.metrics import LAMBDA
from pfp_service.core.route import NO_LIMIT, descent_route
from pfp_service.core.threat import ThreatField
from pfp_service.core.tracking import Route

__all__ = ["Advice", "Bounds", "Need", "StepStatus", "Stepper"]


_GOAL_ZONES: weakref.WeakKeyDictionary[zones.ZoneSet, dict[tuple[float, float], str]] = (
    weakref.WeakKeyDictionary()
)
_GOALS_PER_ZONES = 4096  # goals remembered per zone set (forgotten all at once past it)


def _zone_at_goal(zs: zones.ZoneSet, goal: tuple[float, float]) -> str:
    """``zs.zone_at(*goal)``, asked once per zone set and goal: every step asks it (a zone set is immutable)."""
    per = _GOAL_ZONES.get(zs)
    if per is None:
        per = _GOAL_ZONES[zs] = {}
    got = per.get(goal)
    if got is None:
        if len(per) >= _GOALS_PER_ZONES:
            per.clear()
        got = per[goal] = zs.zone_at(*goal)
    return got


class Stepper(DescentStepper):
    """``DescentStepper`` with deliberation: the look-ahead, escapes from traps, and tracked routes.

    Args: as ``DescentStepper``.
    """

    __slots__ = ()

    def __deepcopy__(self, memo: dict[int, object]) -> Stepper:
        """A detached copy (previews, deliberation): shares the immutable parts, copies the state."""
        new = Stepper.__new__(Stepper)
        for name in DescentStepper.__slots__:  # numbers, tuples, flags and the parameters: immutable, shared
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
    def escape_steps(self) -> int:
        """Advisories given while escaping (status ``escaping``)."""
        return self._escaper.escape_steps if self._escaper is not None else 0

    @property
    def escapes(self) -> list[str]:
        """The strategy of each escape committed to, in order."""
        return list(self._escaper.log) if self._escaper is not None else []

    def held(self) -> None:
        """The unit holds by order (it yields right of way): no progress is no trap; judge afresh when it goes."""
        steprule.reset_watch(self._unit)

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

    def _zoned(self, field: ThreatField, x: float, y: float) -> Advice | None:
        """What keep-out zones decide before descent: a goal in a zone, or a unit in one.

        A goal in a zone is ``trapped`` ("the goal lies in zone Z"); a unit in a
        zone leaves it by the shortest way out first (an escape run, ``leave
        zone Z``), or is ``trapped`` when there is none.  ``None``: descend.
        """
        zones = field.zones
        goal_in = _zone_at_goal(zones, self.goal)
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
        """Plain descent is trapped here: escape (off the loop when deferring), or the verdict stands."""
        if self.params.escape == "none" or field is None or self._ghost:
            return super()._trapped(field, x, y, level, dist, reason)
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
        return run.left_to(self.goal)

    def route_ahead(self, x: float, y: float, steps: int) -> list[tuple[float, float]] | None:
        """A ghost's next ``steps`` positions from ``(x, y)`` on the committed route (``EscapeRun.ahead``).

        ``None`` when there is no route, a standing verdict, or the route may
        end within those steps: then walk a ghost (``plan.walk_many``).
        """
        if self._run is None or self._terminal is not None:
            return None
        return self._run.ahead(self._unit, x, y, steps)

    def route_ahead_points(self, x: float, y: float, steps: int) -> np.ndarray | None:
        """``route_ahead`` as an array ``(n, 2)`` (``EscapeRun.ahead_points``)."""
        if self._run is None or self._terminal is not None:
            return None
        return self._run.ahead_points(self._unit, x, y, steps)

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
        status, why = run._said or run.said()
        # per unit on a route, each report of the live tick (bench row: `pfp bench service`): a
        # NamedTuple made from its fields in order, without its Python-level __new__
        return _tuple(Advice, (status, dx, dy, level, dist, why, False, reach, tx, ty, route))

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
        reach = ahead if ahead < dist else dist
        if reach <= move:
            return move
        if field.zones:  # the way to the pursuit point may cut a zone's corner
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
