"""Whether the world still hears a unit: staleness, forgetting, token debounce and push re-sends.

A unit is fresh while it reports.  Silent for ``unit_stale_s``, or its
liveliness token gone for the whole ``liveliness_debounce_s``, it goes stale
(a ``stale`` event; it gets no directions); stale for ``unit_forget_s`` it
is forgotten (a ``forgotten`` event).  A direction no report asked for (a
push) is sent again every ``push_retry_s``, up to ``push_retries`` times,
until the unit's next report is answered: directions go out with congestion
control DROP, so a burst may lose some.  Each rule is a timer on the world's
heap, looked at again when due.  Liveness decides; the units' owner
(``units.Units``) writes what its verdicts change (fresh, stale, forgotten).
Pure values: ``now`` is a parameter.
"""

from __future__ import annotations

from pfp_service.wire import Direction, DirectionStatus, ForgottenEvent, StaleEvent, UnitState
from pfp_service.world.events import Outputs, WorldSettings
from pfp_service.world.timers import Timers
from pfp_service.world.units import UnitRecord, Units

__all__ = ["UNIT_TIMERS", "Liveness"]

UNIT_TIMERS = ("silence", "token", "push", "forget")  # the kinds of timer ``Liveness.due`` answers
# pushes sent again in one ``apply`` at most: a wave's re-sends come due together (270 puts in one tick, 8 ms of
# the loop), so the rest wait ``RESEND_LATER_S`` each time, a few ticks in all (BENCHMARKS.md, issue 32)
RESENDS_PER_APPLY = 32
RESEND_LATER_S = 0.002
_MOVING = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)


class Liveness:
    """The liveness rules of the units in ``book``, on the world's ``timers``."""

    def __init__(self, settings: WorldSettings, book: Units, timers: Timers) -> None:
        self.settings = settings
        self.book = book
        self.timers = timers
        self.pushes = 0  # directions sent without a report asking
        self.pushes_resent = 0
        self._resending = (float("nan"), 0)  # the apply's ``now`` and the pushes sent again in it

    def counts(self) -> dict[str, int]:
        return {"pushes": self.pushes, "pushes_resent": self.pushes_resent}

    def made(self, rec: UnitRecord, now: float) -> None:
        """A unit's record was made; one not heard from yet is forgotten in time unless it reports."""
        if rec.stale and self.settings.unit_forget_s is not None:
            self.timers.set(now + self.settings.unit_forget_s, "forget", rec.id)

    def reported(self, rec: UnitRecord, state: UnitState, now: float) -> None:
        """A report: the unit is fresh, and is stale again if it falls silent."""
        kind = state.kind.value if state.kind is not None else None
        told_to_move = rec.last_vector is not None and rec.last_status in _MOVING
        x, y = state.position[0], state.position[1]
        rec.progress.report(x, y, state.t, now, state.speed_mps, told_to_move)
        self.book.reported(rec, (x, y), state.seq, kind, now, rec.progress.speed_mps)
        if state.mobility is not None and state.mobility != rec.mobility:  # a class named anew: kept
            self.book.classed(rec, state.mobility)
        if not rec.silence_timer:
            rec.silence_timer = True
            self.timers.set(now + self.settings.unit_stale_s, "silence", rec.id)

    def token(self, rec: UnitRecord, alive: bool, now: float) -> None:
        """The unit's liveliness token came or went; gone, it counts once the debounce ends."""
        if alive:
            rec.token_gone_since = None
        elif rec.token_gone_since is None:
            rec.token_gone_since = now
            self.timers.set(now + self.settings.liveliness_debounce_s, "token", rec.id)

    def due(self, kind: str, rec: UnitRecord, now: float, out: Outputs) -> None:
        """A unit timer of ``kind`` (``UNIT_TIMERS``) is due: look again, and act if it still holds."""
        s = self.settings
        if kind == "silence" and now - rec.last_seen <= s.unit_stale_s:  # heard since: look again when due
            self.timers.set(max(rec.last_seen + s.unit_stale_s, now) + 1e-9, "silence", rec.id)
        elif kind == "silence":
            rec.silence_timer = False
            self._go_stale(rec, now, f"silent for {now - rec.last_seen:.3g} s", out)
        elif kind == "token":
            gone = rec.token_gone_since
            if gone is not None and now - gone >= s.liveliness_debounce_s:
                self._go_stale(rec, now, "liveliness token gone", out)
        elif kind == "push" and rec.push is not None and rec.push_tries > 0 and not rec.stale:
            at, n = self._resending
            n = n + 1 if at == now else 1
            self._resending = (now, n)
            if n > RESENDS_PER_APPLY:  # enough for this apply: the next one's, or the one after
                self.timers.set(now + RESEND_LATER_S, "push", rec.id)
                return
            rec.push_tries -= 1
            self.pushes_resent += 1
            out.directions.append(rec.push)
            if rec.push_tries:
                self.timers.set(now + s.push_retry_s, "push", rec.id)
        elif kind == "forget" and _forgettable(rec, now, s.unit_forget_s):
            stale_s = now - rec.stale_since if rec.stale_since is not None else 0.0
            self.book.forget(rec)
            if rec.owned:  # another shard's unit, unheard here since its shard went: its owner speaks for it
                out.events.append(ForgottenEvent(planner=s.planner_id, unit=rec.id, stale_s=stale_s))

    def pushed(self, fresh: list[Direction], now: float) -> None:
        """Directions that went out in a batch: those no report of the batch asked for are pushes."""
        s = self.settings
        for d in fresh:
            rec = self.book.records.get(d.unit)
            if rec is None or rec.last_seen >= now:  # answering a report of this batch
                continue
            if (rec.push is None or rec.push_tries == 0) and s.push_retries > 0:
                self.timers.set(now + s.push_retry_s, "push", rec.id)
            rec.push, rec.push_tries = d, s.push_retries
            self.pushes += 1

    def _go_stale(self, rec: UnitRecord, now: float, reason: str, out: Outputs) -> None:
        if self.book.go_stale(rec, now):
            assert rec.position is not None
            p = self.settings.planner_id
            if (
                rec.owned
            ):  # under --cluster a planner hears only its own shards: another's unit is its to report
                out.events.append(StaleEvent(planner=p, unit=rec.id, position=rec.position, reason=reason))
            if self.settings.unit_forget_s is not None:
                self.timers.set(now + self.settings.unit_forget_s, "forget", rec.id)


def _forgettable(rec: UnitRecord, now: float, limit_s: float | None) -> bool:
    """Whether a unit has been stale for ``limit_s`` (``None``: never forgotten)."""
    return (
        rec.stale and rec.stale_since is not None and limit_s is not None and now - rec.stale_since >= limit_s
    )
