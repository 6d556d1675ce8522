"""The Zenoh wiring of the planner: thin callbacks, one planning loop, one preview worker.

Callbacks only decode and enqueue (positions latest-wins per unit).  The
planning loop drains the queues in micro-batches, applies them to the
``World`` and computes every pending unit's direction in one vectorised call.
Previews run on their own thread so a long one never delays a direction.
"""

from __future__ import annotations

import collections
import contextlib
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec
import zenoh

from pfp_service import __version__
from pfp_service.errors import InputError
from pfp_service.service.config import ServeConfig
from pfp_service.service.log import get_logger
from pfp_service.service.preview import preview
from pfp_service.service.world import World, WorldSettings
from pfp_service.wire import (
    ArrivedEvent,
    Direction,
    DirectionStatus,
    ErrorReply,
    PlannerStatus,
    RejectedEvent,
    ReplanEvent,
    TrappedEvent,
    decode_goal,
    decode_preview_request,
    decode_threat,
    decode_unit_state,
    encode,
    keys,
)

__all__ = ["PlannerNode"]

log = get_logger("node")
_JSON = zenoh.Encoding.APPLICATION_JSON


class _Latency:
    """Recent planning latencies (receipt of a state to publication of its direction)."""

    def __init__(self, size: int = 4096) -> None:
        self._samples: collections.deque[float] = collections.deque(maxlen=size)

    def add(self, seconds: float) -> None:
        self._samples.append(seconds)

    def quantiles_ms(self) -> tuple[float | None, float | None]:
        if not self._samples:
            return None, None
        s = sorted(self._samples)
        return 1e3 * s[len(s) // 2], 1e3 * s[min(len(s) - 1, int(0.99 * len(s)))]


class PlannerNode:
    """One planner of one mission on an open Zenoh session.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        cfg: the service configuration.
        clock: monotonic seconds; the world model sees only this.
    """

    def __init__(
        self, session: zenoh.Session, cfg: ServeConfig, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.session = session
        self.cfg = cfg
        self.clock = clock
        self.world = World(
            WorldSettings(
                planner=cfg.planner_params(),
                threat_ttl_s=cfg.threat_ttl_s,
                unit_stale_s=cfg.unit_stale_s,
                liveliness_debounce_s=cfg.liveliness_debounce_s,
                lookahead=cfg.lookahead,
                bounds=cfg.bounds_tuple(),
            )
        )
        self.started = clock()
        self.counters = {"msgs_in": 0, "msgs_out": 0, "rejected": 0}
        self.latency = _Latency()
        self._lock = threading.Lock()
        self._states: dict[str, tuple[Any, float]] = {}
        self._inbox: collections.deque[tuple[str, str, Any]] = collections.deque()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._world_lock = threading.Lock()
        self._previews: queue.Queue[Any] = queue.Queue(maxsize=256)
        self._publishers: dict[str, Any] = {}
        self._declared: list[Any] = []
        self._threads: list[threading.Thread] = []
        self._snapshot = self._status()

    # -- lifecycle --------------------------------------------------------------
    def start(self) -> None:
        m = self.cfg.mission
        s = self.session
        self._declared += [
            s.declare_subscriber(keys.unit_states(m), self._on_state),
            s.declare_subscriber(keys.goals(m), self._on_goal),
            s.declare_subscriber(keys.threats(m), self._on_threat),
            s.liveliness().declare_subscriber(keys.alive_units(m), self._on_alive, history=True),
            s.declare_queryable(keys.previews(m), self._on_preview),
            s.declare_queryable(keys.planner_status(m, self.cfg.planner_id), self._on_status),
            s.liveliness().declare_token(keys.alive_planner(m, self.cfg.planner_id)),
        ]
        for target, name in ((self._loop, "pfp-plan"), (self._preview_worker, "pfp-preview")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)
        log.info("planner ready", extra={"fields": {"mission": m, "planner": self.cfg.planner_id}})

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        self._previews.put(None)
        for t in self._threads:
            t.join(timeout=1.0)
        for d in [*self._declared, *self._publishers.values()]:
            with contextlib.suppress(Exception):  # already gone with the session: nothing to release
                d.undeclare()
        self._declared.clear()
        self._publishers.clear()

    # -- callbacks: decode and enqueue, nothing more -----------------------------
    def _reject(self, key: str, err: InputError) -> None:
        self._push("reject", key, err)

    def _push(self, kind: str, ident: str, payload: Any) -> None:
        with self._lock:
            self._inbox.append((kind, ident, payload))
        self._wake.set()

    def _on_state(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            uid = keys.parse(key).id
            msg = decode_unit_state(sample.payload.to_bytes(), self.cfg.bounds)
        except InputError as err:
            self._reject(key, err)
            return
        with self._lock:
            self._states[uid] = (msg, self.clock())
        self._wake.set()

    def _put_or_delete(self, sample: zenoh.Sample, decode: Callable[..., Any], put: str, delete: str) -> None:
        key = str(sample.key_expr)
        try:
            ident = keys.parse(key).id
            if sample.kind == zenoh.SampleKind.DELETE:
                self._push(delete, ident, None)
            else:
                self._push(put, ident, decode(sample.payload.to_bytes(), self.cfg.bounds))
        except InputError as err:
            self._reject(key, err)

    def _on_goal(self, sample: zenoh.Sample) -> None:
        self._put_or_delete(sample, decode_goal, "goal", "cancel")

    def _on_threat(self, sample: zenoh.Sample) -> None:
        self._put_or_delete(sample, decode_threat, "threat", "unthreat")

    def _on_alive(self, sample: zenoh.Sample) -> None:
        try:
            uid = keys.parse(str(sample.key_expr)).id
        except InputError:
            return
        self._push("alive", uid, sample.kind == zenoh.SampleKind.PUT)

    def _on_preview(self, query: zenoh.Query) -> None:
        try:
            self._previews.put_nowait(query)
        except queue.Full:
            query.reply_err(
                encode(ErrorReply(error="planner busy: too many previews queued", field="$")), encoding=_JSON
            )

    def _on_status(self, query: zenoh.Query) -> None:
        # the planning loop refreshes the snapshot every tick; the callback never touches the world
        snap = self._snapshot
        snap = msgspec.structs.replace(snap, uptime_s=max(self.clock() - self.started, 0.0))
        query.reply(query.key_expr, encode(snap), encoding=_JSON)

    # -- status -------------------------------------------------------------------
    def _status(self) -> PlannerStatus:
        p50, p99 = self.latency.quantiles_ms()
        units = list(self.world.units.values())
        return PlannerStatus(
            planner=self.cfg.planner_id,
            mission=self.cfg.mission,
            version=__version__,
            uptime_s=max(self.clock() - self.started, 0.0),
            units=len(units),
            units_stale=sum(1 for u in units if u.stale),
            threats=len(self.world.field),
            msgs_in=self.counters["msgs_in"],
            msgs_out=self.counters["msgs_out"],
            rejected=self.counters["rejected"],
            latency_p50_ms=p50,
            latency_p99_ms=p99,
        )

    # -- the planning loop ------------------------------------------------------------
    def _loop(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(self.cfg.tick_s)
            self._wake.clear()
            try:
                self._tick()
            except Exception:  # never let one bad batch kill the planner; say so loudly
                log.exception("planning loop error")

    def _tick(self) -> None:
        with self._lock:
            inbox, self._inbox = self._inbox, collections.deque()
            states, self._states = self._states, {}
        now = self.clock()
        dirty: set[str] = set()
        replan: list[str] = []
        w = self.world
        with self._world_lock:
            for kind, ident, payload in inbox:
                self.counters["msgs_in"] += 1
                if kind == "reject":
                    self._publish_reject(ident, payload)
                    continue
                try:
                    dirty |= self._apply(kind, ident, payload, now, replan)
                except Exception as exc:  # a message the world cannot take: reject it, keep the rest
                    log.exception("could not apply message", extra={"fields": {"kind": kind, "id": ident}})
                    self._publish_reject(
                        self._key_of(kind, ident), InputError("$", f"could not apply: {exc}")
                    )
            for uid, (msg, _t) in states.items():
                self.counters["msgs_in"] += 1
                dirty |= w.apply_state(uid, msg, now)
            more, expired, stale = w.expire(now)
            dirty |= more
            for tid in expired:
                replan.append(f"threat {tid} expired")
                log.info("threat expired", extra={"fields": {"threat": tid}})
            for uid in stale:
                log.warning("unit stale", extra={"fields": {"unit": uid}})
            previous = {uid: w.units[uid].last_status for uid in dirty if uid in w.units}
            directions = self._directions(dirty) if dirty else []
            self._snapshot = self._status()
        for d in directions:
            self._publish_direction(d, previous.get(d.unit))
        done = self.clock()
        for _msg, t_recv in states.values():
            self.latency.add(done - t_recv)
        if replan:
            guided = sorted(u.unit for u in directions if u.status is not DirectionStatus.NO_GOAL)
            self._event(
                "replan", ReplanEvent(planner=self.cfg.planner_id, units=guided, reason="; ".join(replan))
            )

    def _apply(self, kind: str, ident: str, payload: Any, now: float, replan: list[str]) -> set[str]:
        """Apply one queued message to the world; return the units that need a direction."""
        w = self.world
        if kind == "goal":
            log.info("goal set", extra={"fields": {"unit": ident, "goal": list(payload.position)}})
            return w.apply_goal(ident, payload, now)
        if kind == "cancel":
            had = ident in w.units and w.units[ident].goal is not None
            if had:
                log.info("goal cancelled", extra={"fields": {"unit": ident}})
            return w.cancel_goal(ident)
        if kind == "threat":
            changed = w.apply_threat(ident, payload, now)
            replan.append(f"threat {ident} put")
            log.info("threat put", extra={"fields": {"threat": ident, "affected": len(changed)}})
            return changed
        if kind == "unthreat":
            known = ident in w.threat_ids()
            changed = w.remove_threat(ident)
            if known:
                replan.append(f"threat {ident} removed")
                log.info("threat removed", extra={"fields": {"threat": ident}})
            return changed
        if kind == "alive":
            w.liveliness(ident, payload, now)
        return set()

    def _key_of(self, kind: str, ident: str) -> str:
        m = self.cfg.mission
        return keys.threat(m, ident) if kind in ("threat", "unthreat") else keys.unit_goal(m, ident)

    def _directions(self, dirty: set[str]) -> list[Direction]:
        """All pending directions in one call; if that fails, unit by unit, so one bad unit cannot starve the rest."""
        try:
            return self.world.directions(dirty)
        except Exception:
            log.exception("batch planning failed; planning unit by unit")
        out: list[Direction] = []
        for uid in sorted(dirty):
            try:
                out += self.world.directions({uid})
            except Exception:
                log.exception("planning failed", extra={"fields": {"unit": uid}})
        return out

    # -- output -----------------------------------------------------------------------
    def _publish_direction(self, d: Direction, before: DirectionStatus | None) -> None:
        key = keys.unit_direction(self.cfg.mission, d.unit)
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = self.session.declare_publisher(
                key,
                encoding=_JSON,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.INTERACTIVE_HIGH,
                express=True,
            )
        pub.put(encode(d))
        self.counters["msgs_out"] += 1
        if d.status is not before:
            rec = self.world.units.get(d.unit)
            pos = rec.position if rec is not None and rec.position is not None else (0.0, 0.0)
            fields = {"unit": d.unit, "status": d.status.value}
            if d.status is DirectionStatus.ARRIVED:
                self._event(
                    "arrived",
                    ArrivedEvent(
                        planner=self.cfg.planner_id,
                        unit=d.unit,
                        position=pos,
                        distance_to_goal=d.distance_to_goal or 0.0,
                    ),
                )
                log.info("unit arrived", extra={"fields": fields})
            elif d.status is DirectionStatus.TRAPPED:
                self._event(
                    "trapped",
                    TrappedEvent(planner=self.cfg.planner_id, unit=d.unit, position=pos, reason=d.reason),
                )
                log.warning("unit trapped", extra={"fields": {**fields, "reason": d.reason}})

    def _event(self, kind: str, ev: Any) -> None:
        if ev.t is None:  # events carry wall-clock time (Unix seconds); planning never reads it
            ev = msgspec.structs.replace(ev, t=time.time())
        self.session.put(keys.event(self.cfg.mission, kind), encode(ev), encoding=_JSON)
        self.counters["msgs_out"] += 1

    def _publish_reject(self, key: str, err: InputError) -> None:
        self.counters["rejected"] += 1
        fields: dict[str, Any] = {"key": key, "field": err.path or "$", "reason": err.reason}
        try:
            parsed = keys.parse(key)
            if parsed.kind.value.startswith("unit"):
                fields["unit"] = parsed.id
        except InputError:
            pass
        log.warning("rejected input", extra={"fields": fields})
        self._event(
            "rejected",
            RejectedEvent.of(key, err, planner=self.cfg.planner_id),
        )

    # -- previews ---------------------------------------------------------------------
    def _preview_worker(self) -> None:
        while True:
            query = self._previews.get()
            if query is None:
                return
            try:
                self._answer_preview(query)
            except Exception:
                log.exception("preview failed")
                query.reply_err(
                    encode(ErrorReply(error="internal error while previewing", field="$")), encoding=_JSON
                )
            finally:
                query.drop()

    def _answer_preview(self, query: zenoh.Query) -> None:
        key = str(query.key_expr)
        try:
            uid = keys.parse(key).id
            payload = query.payload.to_bytes() if query.payload is not None else b""
            request = decode_preview_request(payload, self.cfg.bounds) if payload else None
            with self._world_lock:
                view = self.world.view(uid)
            result = preview(
                view,
                uid,
                request,
                self.clock,
                self.cfg.preview_budget_ms / 1e3,
                self.cfg.preview_max_iter,
            )
        except InputError as err:
            query.reply_err(encode(ErrorReply.of(err)), encoding=_JSON)
            return
        query.reply(key, encode(result), encoding=_JSON)
