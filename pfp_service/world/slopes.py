"""A unit's own slope limit over terrain: the barrier sets of the overrides units ask for, built off the loop.

A unit whose mobility overrides ``max_slope_deg`` (``world.mobility.slope_limit``:
whole degrees) plans round the ground steeper than that limit.  The classes'
own limits (``core.mobility.CLASS_LIMITS``) are built when the terrain loads
and always held; an override's set is not, and building one takes 0.5-1.3 s
over the Jacksboro DEM (docs/terrain.md, BENCHMARKS.md), so it is never
built on the planning loop.  ``Slopes`` is the world's book of them:

- ``planned(wanted)`` is the limit a unit wanting ``wanted`` is planned at
  now: its own once its set has landed, else the steepest class limit not
  above it (``core.mobility.planned_limit``, the safe side, as before this
  book), and the first time, it asks for the set (``SlopeAsk``, drained into
  ``Outputs.slopes`` by ``drain``).  The node builds it off the loop
  (``node.terrain.Sights``) and hands it back as a ``SlopeLanded``.
- ``landed`` takes it (versioned by the ask's serial: a landing for an ask
  dropped since is dropped), and ``land`` in this module re-judges at once
  every unit that wants it, as a state whose class moves its limit does
  (``units.Units.rejudge``: its verdict and any deliberation under the old
  barriers dropped), and says so in a ``replan`` event.
- A build that fails, or has not landed ``SLOPE_WAIT_S`` after the ask, is a
  value: the units keep planning at the class limit, a ``replan`` event
  says why, and the limit is asked again no sooner than ``SLOPE_RETRY_S``.
- Bounded: at most ``SLOPE_SETS`` override sets held or being built at once.
  When they are all taken, the least recently planned-at set no unit wants
  is evicted; if every one is wanted, the new limit is beyond the cap: its
  units plan at the class limit and a ``replan`` event says so (asked again
  after ``SLOPE_RETRY_S``).  Sets of more than ``SLOPE_SET_ZONES`` zones are
  not held (failure as a value, as above).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pfp_service.core.mobility import CLASS_LIMITS, planned_limit
from pfp_service.wire.messages import ReplanEvent
from pfp_service.world.terrain import SlopeAsk, SlopeLanded

if TYPE_CHECKING:
    from pfp_service.core.zones import Zone
    from pfp_service.world.events import Batch

__all__ = ["SLOPE_RETRY_S", "SLOPE_SETS", "SLOPE_SET_ZONES", "SLOPE_WAIT_S", "Slopes", "land"]

# Override sets held (or being built) at once, besides the classes' own.  A set over the Jacksboro DEM holds
# 1,000-2,500 zones, 2-5 MB (BENCHMARKS.md); each limit in use also keeps a zone set and a field in
# ``Records`` (``MAX_SLOPE_SETS``).  Eight is a few distinct overrides per class, 40 MB at most over a DEM
# the Jacksboro's size, and a 9th distinct limit is rare enough to say so rather than evict a set in use.
SLOPE_SETS = 8
SLOPE_SET_ZONES = 20_000  # zones in one override set at most: a bound on its memory (about 40 MB)
# an ask not landed this long after it is a failure, its units at the class limit meanwhile (safe): room for a
# worker started fresh, where no fork server holds the terrain, to load the DEM before it builds (node.terrain)
SLOPE_WAIT_S = 90.0
SLOPE_RETRY_S = 60.0  # a limit whose set failed, or that was beyond the cap, is asked again after this


@dataclass(slots=True)
class Slopes:
    """The override slope limits' barrier sets: held (LRU), asked, and those that failed or did not fit."""

    in_use: Callable[[], Iterable[int | None]]  # the limits the units want now (``world.mobility.limit_of``)
    held: OrderedDict[int, tuple[Zone, ...]] = field(default_factory=OrderedDict)
    asked: dict[int, tuple[int, float]] = field(default_factory=dict)  # limit: (serial, asked at)
    failed: dict[int, float] = field(default_factory=dict)  # limit: when it may be asked again
    evicted: list[int] = field(default_factory=list)  # since ``Records`` last purged its caches
    _asks: list[SlopeAsk] = field(default_factory=list)  # to go out (``drain``)
    _said: list[tuple[int, str]] = field(default_factory=list)  # events to go out: (limit, why)
    _serial: int = 0
    _now: float = 0.0

    def planned(self, wanted: int | None) -> int | None:
        """The limit a unit wanting ``wanted`` whole degrees is planned at now (``None``: the planner's class);
        a limit neither a class's nor held is asked for (at most once at a time)."""
        if wanted is None or wanted in CLASS_LIMITS:
            return wanted
        if wanted in self.held:
            self.held.move_to_end(wanted)
            return wanted
        safe = planned_limit(wanted)
        if safe is None:  # below every class (refused on the wire; put in-process): the planner's, as ever
            return None
        if wanted not in self.asked and self.failed.get(wanted, -1.0) <= self._now:
            self._ask(wanted)
        return safe

    def _ask(self, wanted: int) -> None:
        self.failed.pop(wanted, None)
        if len(self.held) + len(self.asked) >= SLOPE_SETS:
            wanted_now = set(self.in_use())
            spare = next((lim for lim in self.held if lim not in wanted_now), None)  # least recently used
            if spare is None:
                self.failed[wanted] = self._now + SLOPE_RETRY_S
                self._said.append((wanted, f"beyond the {SLOPE_SETS} override slope sets held"))
                return
            del self.held[spare]
            self.evicted.append(spare)
        self._serial += 1
        self.asked[wanted] = (self._serial, self._now)
        self._asks.append(SlopeAsk(wanted, self._serial))

    def landed(self, done: SlopeLanded, now: float) -> str | None:
        """Take ``done``: what the event says of it (``None``: dropped, for an ask no longer standing)."""
        asked = self.asked.get(done.limit)
        if asked is None or asked[0] != done.serial:
            return None
        del self.asked[done.limit]
        if done.zones is None or len(done.zones) > SLOPE_SET_ZONES:
            self.failed[done.limit] = now + SLOPE_RETRY_S
            why = done.error or f"{len(done.zones or ())} zones, more than {SLOPE_SET_ZONES}"
            return f"slope barriers for {done.limit}deg not built ({why})"
        self.held[done.limit] = done.zones
        return f"slope barriers for {done.limit}deg built"

    def expire(self, now: float) -> None:
        """Give up the asks ``SLOPE_WAIT_S`` old (their landing is dropped), and note ``now``."""
        self._now = now
        for lim, (_, at) in list(self.asked.items()):
            if now - at >= SLOPE_WAIT_S:
                del self.asked[lim]
                self.failed[lim] = now + SLOPE_RETRY_S
                self._said.append((lim, f"not built within {SLOPE_WAIT_S:g} s"))

    def drain(self) -> tuple[list[SlopeAsk], list[tuple[int, str]]]:
        """The asks to send and the failures to say since the last drain."""
        out = (self._asks, self._said)
        self._asks, self._said = [], []
        return out

    def counts(self) -> dict[str, int]:
        """How many override sets are held, being built, and failed or beyond the cap (tests, the docs)."""
        return {"held": len(self.held), "asked": len(self.asked), "failed": len(self.failed)}


def land(records: Any, done: SlopeLanded, b: Batch, planner: str) -> None:
    """A set landed (``SlopeLanded``): taken, and every guided unit that wants its limit re-judged at once and
    directed afresh under it (``records``: ``world_records.Records``)."""
    said = records.slopes.landed(done, b.now)
    if said is None:
        return
    units = records.wanting(done.limit)
    if done.zones is not None and done.limit in records.slopes.held:
        for rec in units:
            records.book.rejudge(rec)
            b.dirty.add(rec.id)
        said += ": re-judged at it"
    else:
        said += f": planned at {planned_limit(done.limit)}deg"
    b.out.events.append(_event(planner, [r.id for r in units], said))


def said(records: Any, b: Batch, planner: str) -> None:
    """At the end of an apply: give up the asks too old, send those made since the last apply, and say the
    limits that failed or did not fit."""
    records.slopes.expire(b.now)
    asks, failures = records.slopes.drain()
    b.out.slopes.extend(asks)
    for lim, why in failures:
        units = [r.id for r in records.wanting(lim)]
        b.out.events.append(_event(planner, units, f"{lim}deg {why}: planned at {planned_limit(lim)}deg"))


def _event(planner: str, units: list[str], reason: str) -> ReplanEvent:
    from pfp_service.wire.messages.structs import MAX_EVENT_ITEMS

    shown = sorted(units)
    return ReplanEvent(
        planner=planner,
        units=shown[:MAX_EVENT_ITEMS],
        reason=reason,
        more_units=max(0, len(shown) - MAX_EVENT_ITEMS),
    )
