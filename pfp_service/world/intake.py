"""What waits for the world's next batch: the bounded intake the node's callbacks enqueue into.

Inputs keep their order; unit states are latest-wins per unit (a unit
reporting again keeps its place in line, its newest state replacing the
older; a class it named, ``mobility``, is kept on the newest if that names
none, since a state without one changes nothing, ``world.mobility``).  A
tick takes a bounded slice of each, the longest waiting first, so a storm is
spread over ticks and no tick holds up the rest.  Past
``inputs_max`` an input is refused and counted, except a deliberation's
answer (the unit's job would stand forever; they are bounded by the jobs
asked, one per unit).  What was refused here, or at the node's other queues
(``refused``), goes to the world with the next tick (``Tick.shed``): the world
keeps the one overload count.  Not thread-safe (the node holds its lock);
no clock: a state's receipt time is given.
"""

from __future__ import annotations

import collections
import itertools
from dataclasses import dataclass, field

import msgspec

from pfp_service.wire import GoalMobility, UnitState
from pfp_service.world.events import Deliberated, Input

__all__ = ["Intake", "Slice"]


@dataclass(slots=True)
class Slice:
    """One tick's share: inputs in order, states by unit (with when each came), and the count refused."""

    inputs: collections.deque[Input] = field(default_factory=collections.deque)
    states: dict[str, tuple[UnitState, float]] = field(default_factory=dict)
    shed: int = 0
    more: bool = False  # something still waits: the next tick should come at once


class Intake:
    """Inputs in order and unit states latest-wins, bounded and taken in slices."""

    def __init__(self, inputs_max: int, inputs_per_tick: int, units_per_tick: int) -> None:
        self.inputs_max = inputs_max
        self.inputs_per_tick = inputs_per_tick
        self.units_per_tick = units_per_tick
        self._inputs: collections.deque[Input] = collections.deque()
        self._states: dict[str, tuple[UnitState, float]] = {}
        # the class a waiting state named: kept if a newer state of its unit names none
        self._named: dict[str, GoalMobility] = {}
        self._shed = 0

    def __len__(self) -> int:
        return len(self._inputs) + len(self._states)

    def put(self, item: Input) -> bool:
        """Queue an input; ``False``: refused (the intake is full), and counted."""
        if len(self._inputs) >= self.inputs_max and not isinstance(item, Deliberated):
            self._shed += 1
            return False
        self._inputs.append(item)
        return True

    def state(self, unit: str, msg: UnitState, received: float) -> None:
        """A unit's newest state; an older one still waiting is replaced, in its place in line."""
        if msg.mobility is not None:  # rare: a state without a class pays this one read
            self._named[unit] = msg.mobility
        self._states[unit] = (msg, received)

    def refused(self, n: int = 1) -> None:
        """Count inputs refused at another of the node's queues (writes, queries)."""
        self._shed += n

    def take(self) -> Slice:
        """This tick's slice: at most ``inputs_per_tick`` inputs and ``units_per_tick`` states."""
        got = Slice(shed=self._shed)
        self._shed = 0
        if len(self._inputs) <= self.inputs_per_tick:
            got.inputs, self._inputs = self._inputs, collections.deque()
        else:
            got.inputs = collections.deque(self._inputs.popleft() for _ in range(self.inputs_per_tick))
        if len(self._states) <= self.units_per_tick:
            got.states, self._states = self._states, {}
        else:  # the longest waiting first (a unit reporting again keeps its place: latest wins)
            first = list(itertools.islice(self._states, self.units_per_tick))
            got.states = {u: self._states.pop(u) for u in first}
        if self._named:
            self._carry(got.states)
        got.more = bool(self._inputs or self._states)
        return got

    def _carry(self, states: dict[str, tuple[UnitState, float]]) -> None:
        """The class a replaced state named, onto the newest state taken that names none."""
        for unit in [u for u in self._named if u in states]:
            mob = self._named.pop(unit)
            msg, received = states[unit]
            if msg.mobility is None:
                states[unit] = (msgspec.structs.replace(msg, mobility=mob), received)
