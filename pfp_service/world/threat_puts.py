"""A threat put, removed or expired, and over terrain held for its sight: what each puts in the world's batch.

A threat put takes force at once, with what changed (``Batch.touched``,
``Batch.changes``) for the world to re-judge the units it reaches -- unless
the mission plans over terrain and the threat's window of lowest visible
heights has not landed (``world.terrain``).  It is then held
(``Records.hold``): its window is asked off the loop (``Outputs.sights``),
and it takes force when the window lands (``landed``) or, blind, when
``WorldSettings.sight_wait_s`` has passed (``give_up``, the world's ``sight``
timer).  The ask carries the units' corridors as they stand
(``wave.Corridors``), so the landing's reach is judged with the window off
the loop too (``wave.answered``).  A world that deliberates inline (tests,
the warm-up) has no loop to keep and computes the window at once.  Pure values: ``now`` is the batch's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from pfp_service.errors import InputError
from pfp_service.wire import ThreatChange, ThreatUpdate, keys
from pfp_service.world import translate, wave
from pfp_service.world.events import Batch, WorldSettings
from pfp_service.world.limits import Limits
from pfp_service.world.terrain import SightLanded, answer
from pfp_service.world.timers import Timers
from pfp_service.world.world_records import Records, ThreatRecord

__all__ = ["Puts", "ThreatPuts"]

Reject = Callable[[str, InputError, Batch, "keys.KeyKind | None"], None]


class Puts:
    """What a kind's inputs are applied with: the world's own ``Records``, ``Timers`` and ``Limits``, and its
    ``reject``."""

    def __init__(self, settings: WorldSettings, rec: Records, timers: Timers, limits: Limits, reject: Reject):
        self.settings, self._rec, self._timers, self._limits, self._reject = (
            settings,
            rec,
            timers,
            limits,
            reject,
        )


class ThreatPuts(Puts):
    """The world's threat inputs."""

    def put(self, tid: str, msg: ThreatUpdate, b: Batch) -> None:
        """A threat put: in force now, or held for its sight (asked, or computed here when inline)."""
        s = self.settings
        if tid not in self._rec.threats and len(self._rec.threats) + len(self._rec.held) >= s.max_threats:
            self._limits.overload += 1
            err = InputError("$", f"planner at max_threats ({s.max_threats})")
            self._reject(keys.threat(s.mission, tid), err, b, keys.KeyKind.THREAT)
            return
        ttl = msg.ttl_s if msg.ttl_s is not None else s.threat_ttl_s
        try:
            threat = translate.threat(msg, tid)
        except translate.ShapeError as exc:  # restored, or a peer's: a write is checked when decoded
            self._reject(keys.threat(s.mission, tid), translate.refusal(exc), b, keys.KeyKind.THREAT)
            return
        new = ThreatRecord(msg, threat, None if ttl is None else b.now + ttl)
        held, ask = self._rec.hold(tid, new, b.now + s.sight_wait_s)
        if ask is not None and s.deliberation == "inline" and s.terrain is not None:  # no loop to keep
            self.landed(answer(s.terrain, ask), b)
        elif ask is not None:  # with the corridors its landing re-judges, judged with the window off the loop
            b.out.sights.append(dataclasses.replace(ask, corridors=self._corridors(tid, b)))
            self._timers.set(b.now + s.sight_wait_s, "sight", tid)
        if not held:
            self._in_force(tid, new, b)

    def landed(self, done: SightLanded, b: Batch) -> None:
        """A threat's window landed: the threat held for it takes force, or one in force blind is masked."""
        got = self._rec.landed(done.threat, done.key, done.window)
        if got is None:  # for a threat since moved or removed
            return
        change, rec = got
        if done.judged is not None:
            b.judged.append(done.judged)
        if change == "put":
            self._in_force(done.threat, rec, b)
        else:  # masked now: the units it reaches are re-judged, as for a put
            b.touched.append(rec.threat)
            b.changes.append(ThreatChange(threat=done.threat, change="put", position=rec.update.position))

    def give_up(self, tid: str, b: Batch) -> None:
        """The ``sight`` timer: a threat still held for its window takes force blind (the safe side)."""
        rec = self._rec.give_up(tid, b.now)
        if rec is not None:
            self._in_force(tid, rec, b)

    def gone(self, t: ThreatRecord | None, tid: str, change: str, b: Batch) -> None:
        """A threat removed or expired (``t``; ``None``: there was none in force)."""
        if t is not None:
            b.touched.append(t.threat)
            b.changes.append(ThreatChange(threat=tid, change=change, position=t.update.position))

    def _corridors(self, tid: str, b: Batch) -> wave.Corridors:
        """The units' corridors as they stand (taken once a batch: a storm of puts shares them), and the
        threat ``tid`` in force now with its window."""
        if b.corridors is None:
            b.corridors = wave.corridors(self._rec.units, self.settings.planner.intensity)
        taken: wave.Corridors = b.corridors
        now_in = self._rec.threats.get(tid)
        if now_in is None:
            return taken
        window = None
        if now_in.seen is not None and self._rec.sight is not None:
            x0, y0, x1, y1 = now_in.seen[3:]  # its key ends with its box
            window = self._rec.sight(now_in.threat, (x0, y0, x1, y1))
        return dataclasses.replace(taken, before=now_in.threat, before_window=window)

    def _in_force(self, tid: str, new: ThreatRecord, b: Batch) -> None:
        old = self._rec.put_threat(tid, new)
        b.touched += [new.threat] if old is None else [old.threat, new.threat]
        if new.expires_at is not None:
            self._timers.set(new.expires_at, "expire", tid)
        b.changes.append(ThreatChange(threat=tid, change="put", position=new.update.position))
