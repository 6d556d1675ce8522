"""Plain steepest descent for one unit, and what the step rule's verdicts mean.

``DescentStepper`` is the stepper without deliberation: it answers each
advisory with one ``steprule`` call (the gradient, arrival, bounds, the final
approach and the trap watch) and turns the verdict into ``Advice``.  A trap is
final here; ``stepper.Stepper`` extends it with the look-ahead, escapes and
tracked routes, and is what every driver uses.  Trap detection (plain descent
has no memory, so this is the only guard):

* *stall*: over the last ``trap_window`` advisories the unit moved less than
  ``0.2 * trap_window * step`` net, i.e. it is oscillating about a point;
* *no progress*: the best distance to goal has not improved by a tolerance in
  ``progress_window`` advisories (a slow creep into a basin or an orbit).

Either one ends plain descent with ``trapped`` and the reason, rather than
running on silently to ``max_iter``.  The verdict stands while the unit stays
where it was trapped; a unit reported more than ``trap_window * step`` away
from that point (a person walked it out) is guided again, judged afresh.
"""

from __future__ import annotations

import math

import numpy as np

from pfp_service.core import steprule, tracking
from pfp_service.core.advice import Advice, Need, StepStatus
from pfp_service.core.escape import Escaper
from pfp_service.core.params import Resolved
from pfp_service.core.route import EscapeRun
from pfp_service.core.threat import ThreatField
from pfp_service.core.tracking import Route

__all__ = ["Bounds", "DescentStepper"]

Bounds = tuple[tuple[float, float], tuple[float, float]]


_tuple = tuple.__new__  # a NamedTuple from all its fields, in order, without its Python-level __new__


class DescentStepper:
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

    @property
    def traps(self) -> int:
        """How many times plain descent was trapped for this goal (or foreseen to be, and went round)."""
        return self._traps

    def _descend(self, field: ThreatField, x: float, y: float) -> Advice:
        """Plain descent at ``(x, y)``: the gradient and the verdict in one compiled call."""
        if self.params.trap_window > steprule.RING_START:  # the ring may need to grow
            self._unit = steprule.roomy(self._unit)
        code, dx, dy, level, dist, move, tx, ty = steprule.descend(
            field.packed, *field.zones.packed(), self._unit, x, y
        )
        return self._judged(field, x, y, level, code, dx, dy, dist, move, tx, ty)

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
        """Plain descent is trapped at ``(x, y)``: the verdict stands (``Stepper`` escapes, where it may)."""
        self._traps += 1
        return self._end(StepStatus.TRAPPED, level, dist, reason, (x, y))

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
