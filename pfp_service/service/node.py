"""The Zenoh wiring of the planner: decode, enqueue, ``world.apply``, publish.

* Callbacks decode and enqueue, nothing more: positions latest-wins per unit,
  everything else in order, queries handed to the loop.  No callback replies
  or puts.
* One planning loop drains the inbox, applies the batch and a ``Tick`` to the
  ``World`` and publishes what it returns.  Every decision is the world's.
* Deliberation jobs the world asks for run on their own pool and come back as
  ``Deliberated`` inputs; previews run on another pool, each with a deadline.
  Neither ever holds up the loop.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import heapq
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import msgspec
import zenoh

from pfp_service import __version__, geojson
from pfp_service.core.params import Resolved
from pfp_service.errors import InputError
from pfp_service.service.config import ServeConfig
from pfp_service.service.log import get_logger
from pfp_service.service.preview import fit_reply, preview
from pfp_service.service.store import Store
from pfp_service.service.world import (
    Deliberated,
    GoalCancelled,
    GoalSet,
    Input,
    InputRejected,
    Job,
    MissionRestored,
    MissionShared,
    PeerPlanner,
    StateReported,
    ThreatPut,
    ThreatRemoved,
    Tick,
    TokenChanged,
    World,
    WorldSettings,
    mission_message,
)
from pfp_service.wire import (
    ErrorReply,
    Event,
    ForgottenEvent,
    PlannerStatus,
    RejectedEvent,
    RestoredEvent,
    decode_goal,
    decode_mission,
    decode_preview_request,
    decode_threat,
    decode_unit_state,
    decode_world_snapshot,
    encode,
    keys,
)
from pfp_service.wire.messages import Goal

__all__ = ["PlannerNode"]

log = get_logger("node")
_JSON = zenoh.Encoding.APPLICATION_JSON
EXPIRY_GRACE_S = 0.05  # a preview still computing this long past its deadline is answered "expired"
SWITCH_INTERVAL_S = 0.0005  # the GIL is handed over this often, so pool threads cannot hold up the loop
INBOX_MAX = 100_000  # queued inputs beyond this are refused and counted (positions are latest-wins anyway)


def world_settings(cfg: ServeConfig) -> WorldSettings:
    """The world's settings from the service configuration."""
    return WorldSettings(
        planner=cfg.planner_params(),
        threat_ttl_s=cfg.threat_ttl_s,
        unit_stale_s=cfg.unit_stale_s,
        liveliness_debounce_s=cfg.liveliness_debounce_s,
        lookahead=cfg.lookahead,
        bounds=cfg.bounds_tuple(),
        mission=cfg.mission,
        planner_id=cfg.planner_id,
        deliberation="deferred",
        deliberation_budget_s=cfg.deliberation_budget_s,
        unit_forget_s=cfg.unit_forget_s,
        max_units=cfg.max_units,
        max_threats=cfg.max_threats,
        origin=cfg.origin,
        cluster=cfg.cluster,
    )


def warm_up(settings: WorldSettings) -> None:
    """Load (or compile) the numba kernels before serving, so no first direction or preview pays for it."""
    from pfp_service.wire import Goal, ThreatUpdate, UnitState

    w = World(dataclasses.replace(settings, deliberation="inline", bounds=None))
    threat = ThreatUpdate(position=(5.0, 5.0), sigma_range=1.0, sigma_lateral=0.7)
    out = w.apply(
        [
            ThreatPut("w", threat),
            StateReported("w", UnitState(position=(0.0, 0.0))),
            GoalSet("w", Goal(position=(10.0, 10.0))),
        ],
        0.0,
    )
    preview(w.view("w"), None, time.monotonic, 5.0, 10_000)
    assert out.directions


class _Answer:
    """One preview query, answered exactly once: by its worker, or by the loop once its deadline passed."""

    def __init__(self, query: zenoh.Query, deadline: float) -> None:
        self.query = query
        self.deadline = deadline
        self.done = False
        self._lock = threading.Lock()

    def _claim(self) -> bool:
        with self._lock:
            if self.done:
                return False
            self.done = True
            return True

    def reply(self, key: str, body: bytes) -> None:
        if self._claim():
            with contextlib.suppress(Exception):  # the querier may be gone
                self.query.reply(key, body, encoding=_JSON)
                self.query.drop()

    def error(self, err: ErrorReply) -> None:
        if self._claim():
            with contextlib.suppress(Exception):
                self.query.reply_err(encode(err), encoding=_JSON)
                self.query.drop()


class _Latency:
    """Recent latencies, receipt of a state to publication of its direction; quantiles when asked."""

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
        clock: monotonic seconds; the world sees only this.
        store: durable state (``Store``); goals and threats are committed to it
            before they are applied, and restored from it at ``start``.
    """

    def __init__(
        self,
        session: zenoh.Session,
        cfg: ServeConfig,
        clock: Callable[[], float] = time.monotonic,
        store: Store | None = None,
    ) -> None:
        self.session = session
        self.store = store
        self._origin = cfg.origin
        self.cfg = cfg
        self.clock = clock
        self.world = World(world_settings(cfg))
        self.started = clock()
        self.counters = {"msgs_in": 0, "msgs_out": 0, "overload": 0}
        self.latency = _Latency()
        self._lock = threading.Lock()
        self._states: dict[str, tuple[Any, float]] = {}
        self._inbox: collections.deque[Input] = collections.deque()
        self._queries: collections.deque[tuple[str, zenoh.Query, float]] = collections.deque()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._declared: list[Any] = []
        self._loop_thread: threading.Thread | None = None
        self._deliberators = ThreadPoolExecutor(cfg.deliberation_workers, thread_name_prefix="pfp-deliberate")
        self._previewers = ThreadPoolExecutor(cfg.preview_workers, thread_name_prefix="pfp-preview")
        self._pending: dict[int, _Answer] = {}  # previews not yet expired by the loop
        self._deadlines: list[tuple[float, int, _Answer]] = []

    # -- lifecycle --------------------------------------------------------------
    def start(self) -> None:
        # Python threads (previews, deliberation) take the GIL for 5 ms at a time by default;
        # measured: loop p99 9.0 ms with two busy preview threads, 2.4 ms at 0.5 ms.
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        warm_up(self.world.settings)
        m, p = self.cfg.mission, self.cfg.planner_id
        s = self.session
        restored = None
        if self.store is not None:
            restored = self.store.restore(time.time())
            self.world.apply(restored.inputs, self.clock())
        self._declared += [
            s.declare_subscriber(keys.unit_states(m), self._on_state),
            s.declare_subscriber(keys.goals(m), self._on_goal),
            s.declare_subscriber(keys.threats(m), self._on_threat),
            s.liveliness().declare_subscriber(keys.alive_units(m), self._on_alive, history=True),
            s.declare_queryable(keys.previews(m), lambda q: self._on_query("preview", q)),
            s.declare_queryable(keys.planner_status(m, p), lambda q: self._on_query("status", q)),
            s.declare_queryable(keys.world(m, p), lambda q: self._on_query("world", q)),
            s.liveliness().declare_subscriber(keys.alive_planners(m), self._on_planner, history=True),
        ]
        if self.cfg.cluster:
            self._declared.append(s.declare_subscriber(keys.unit_missions(m), self._on_mission))
        self._join(s)
        self._declared.append(s.liveliness().declare_token(keys.alive_planner(m, p)))
        if restored is not None:
            ev = RestoredEvent(
                planner=p,
                threats=restored.threats,
                goals=restored.goals,
                missions=restored.missions,
                expired=restored.expired,
            )
            self._event(ev)
        self._loop_thread = threading.Thread(target=self._loop, name="pfp-plan", daemon=True)
        self._loop_thread.start()
        log.info("planner ready", extra={"fields": {"mission": m, "planner": p}})

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._loop_thread is not None:
            self._loop_thread.join(timeout=2.0)
        self._deliberators.shutdown(wait=False, cancel_futures=True)
        self._previewers.shutdown(wait=False, cancel_futures=True)
        for d in self._declared:
            with contextlib.suppress(Exception):  # already gone with the session: nothing to release
                d.undeclare()
        self._declared.clear()

    # -- callbacks: decode and enqueue, nothing more -----------------------------
    def _push(self, item: Input) -> None:
        with self._lock:
            if len(self._inbox) >= INBOX_MAX:
                self.counters["overload"] += 1
                return
            self._inbox.append(item)
        self._wake.set()

    def _on_state(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            uid = keys.parse(key).id
            msg = decode_unit_state(sample.payload.to_bytes(), self.cfg.bounds, self._origin)
        except InputError as err:
            self._push(InputRejected(key, err))
            return
        with self._lock:
            self._states[uid] = (msg, self.clock())
        self._wake.set()

    def _on_goal(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            uid = keys.parse(key).id
            if sample.kind == zenoh.SampleKind.DELETE:
                self._push(GoalCancelled(uid))
            else:
                self._push(
                    GoalSet(uid, decode_goal(sample.payload.to_bytes(), self.cfg.bounds, self._origin))
                )
        except InputError as err:
            self._push(InputRejected(key, err))

    def _on_threat(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            tid = keys.parse(key).id
            if sample.kind == zenoh.SampleKind.DELETE:
                self._push(ThreatRemoved(tid))
            else:
                self._push(
                    ThreatPut(tid, decode_threat(sample.payload.to_bytes(), self.cfg.bounds, self._origin))
                )
        except InputError as err:
            self._push(InputRejected(key, err))

    def _on_alive(self, sample: zenoh.Sample) -> None:
        try:
            uid = keys.parse(str(sample.key_expr)).id
        except InputError:
            return
        self._push(TokenChanged(uid, sample.kind == zenoh.SampleKind.PUT))

    def _join(self, s: zenoh.Session) -> None:
        """What the planners already serving this mission hold: threats, goals and missions, applied at once.

        A planner started after threats and goals were published then guides
        correctly from its first direction.  No reply (a lone planner) costs ~1 ms.
        """
        inputs: list[Input] = []
        for reply in s.get(keys.worlds(self.cfg.mission), timeout=2.0):
            if reply.ok is None:
                continue
            try:
                snap = decode_world_snapshot(reply.ok.payload.to_bytes())
            except InputError:
                continue
            if snap.planner == self.cfg.planner_id:
                continue
            for t in snap.threats:
                update = (
                    t.threat
                    if t.ttl_s is None
                    else msgspec.structs.replace(t.threat, ttl_s=max(t.ttl_s, 1e-3))
                )
                inputs.append(ThreatPut(t.id, update))
            for u in snap.units:
                if u.mission is not None:
                    params = Resolved(**msgspec.structs.asdict(u.mission.params))  # type: ignore[arg-type]
                    inputs.append(MissionRestored(u.id, u.mission.goal, tuple(u.mission.origin), params))  # type: ignore[arg-type]
                elif u.goal is not None:
                    inputs.append(GoalSet(u.id, Goal(position=u.goal)))
        if inputs:
            self.world.apply(inputs, self.clock())
            log.info("joined the mission's planners", extra={"fields": {"inputs": len(inputs)}})
        if self.cfg.cluster:  # let the liveliness history name the peers before the first direction
            time.sleep(0.3)

    def _on_mission(self, sample: zenoh.Sample) -> None:
        try:
            uid = keys.parse(str(sample.key_expr)).id
            if sample.kind == zenoh.SampleKind.PUT:
                self._push(MissionShared(uid, decode_mission(sample.payload.to_bytes())))
        except InputError as err:
            self._push(InputRejected(str(sample.key_expr), err))

    def _on_planner(self, sample: zenoh.Sample) -> None:
        try:
            pid = keys.parse(str(sample.key_expr)).id
        except InputError:
            return
        self._push(PeerPlanner(pid, sample.kind == zenoh.SampleKind.PUT))

    def _on_query(self, kind: str, query: zenoh.Query) -> None:
        with self._lock:
            self._queries.append((kind, query, self.clock()))
        self._wake.set()

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
            queries, self._queries = self._queries, collections.deque()
        now = self.clock()
        batch: list[Input] = list(inbox)
        batch += [StateReported(uid, msg) for uid, (msg, _t) in states.items()]
        batch.append(Tick(now))
        self.counters["msgs_in"] += len(batch) - 1
        if self.store is not None:
            batch = self._commit(batch)
        self._log_inputs(inbox)
        out = self.world.apply(batch, now)
        if self.store is not None and (out.missions or out.events):
            self._record(out)
        for d in out.directions:
            self._put(keys.unit_direction(self.cfg.mission, d.unit), encode(d), direction=True)
        for ev in out.events:
            self._event(ev)
        if self.cfg.cluster:
            for rec in out.missions:
                self._put(
                    keys.unit_mission(self.cfg.mission, rec.unit),
                    encode(mission_message(rec, self.cfg.planner_id)),
                )
        for job in out.jobs:
            self._deliberators.submit(self._deliberate, job)
        done = self.clock()
        for _msg, t_recv in states.values():
            self.latency.add(done - t_recv)
        for kind, query, t_recv in queries:
            self._answer(kind, query, t_recv)
        if self._deadlines:
            self._expire_previews(self.clock())

    def _log_inputs(self, inbox: collections.deque[Input], limit: int = 20) -> None:
        """One line per goal or threat change, at most ``limit`` a tick and a count of the rest."""
        shown = 0
        for inp in inbox:
            if isinstance(inp, GoalSet):
                msg, fields = "goal set", {"unit": inp.unit, "goal": list(inp.goal.position)}
            elif isinstance(inp, GoalCancelled):
                msg, fields = "goal cancelled", {"unit": inp.unit}
            elif isinstance(inp, ThreatPut):
                msg, fields = "threat put", {"threat": inp.threat, "position": list(inp.update.position)}
            elif isinstance(inp, ThreatRemoved):
                msg, fields = "threat removed", {"threat": inp.threat}
            else:
                continue
            shown += 1
            if shown <= limit:
                log.info(msg, extra={"fields": fields})
        if shown > limit:
            log.info("more goal and threat changes", extra={"fields": {"count": shown - limit}})

    def _commit(self, batch: list[Input]) -> list[Input]:
        """Goals and threats are applied only once committed; if the store fails they are refused."""
        assert self.store is not None
        try:
            self.store.commit_inputs(batch, time.time(), self.cfg.threat_ttl_s)
            return batch
        except Exception as exc:
            log.exception("state store failed; goal and threat changes refused")
            kept: list[Input] = []
            m = self.cfg.mission
            for inp in batch:
                if isinstance(inp, GoalSet | GoalCancelled):
                    kept.append(
                        InputRejected(keys.unit_goal(m, inp.unit), InputError("$", f"not stored: {exc}"))
                    )
                elif isinstance(inp, ThreatPut | ThreatRemoved):
                    kept.append(
                        InputRejected(keys.threat(m, inp.threat), InputError("$", f"not stored: {exc}"))
                    )
                else:
                    kept.append(inp)
            return kept

    def _record(self, out: Any) -> None:
        assert self.store is not None
        try:
            self.store.record_missions(out.missions)
            self.store.forget(e.unit for e in out.events if isinstance(e, ForgottenEvent))
        except Exception:
            log.exception("state store failed to record missions")

    def _deliberate(self, job: Job) -> None:
        if job.cancelled:
            return
        try:
            result = job.run(self.clock())
        except Exception:
            log.exception("deliberation failed", extra={"fields": {"unit": job.unit, "kind": job.kind}})
            result = Deliberated(job.unit, job.token, None)
        self._push(result)

    # -- output -----------------------------------------------------------------------
    def _put(self, key: str, payload: bytes, direction: bool = False) -> None:
        if direction:
            self.session.put(
                key,
                payload,
                encoding=_JSON,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.INTERACTIVE_HIGH,
                express=True,
            )
        else:
            self.session.put(key, payload, encoding=_JSON)
        self.counters["msgs_out"] += 1

    def _event(self, ev: Event) -> None:
        ev = msgspec.structs.replace(ev, t=time.time())  # wall-clock time; planning never reads it
        kind = ev.__struct_config__.tag
        self._put(keys.event(self.cfg.mission, str(kind)), encode(ev))
        fields = {k: v for k, v in msgspec.structs.asdict(ev).items() if k not in ("t", "planner")}
        if isinstance(ev, RejectedEvent):
            log.warning("rejected input", extra={"fields": fields})
        else:
            log.info(str(kind), extra={"fields": fields})

    # -- queries ------------------------------------------------------------------------
    def _answer(self, kind: str, query: zenoh.Query, t_recv: float) -> None:
        m, p = self.cfg.mission, self.cfg.planner_id
        if kind == "status":
            query.reply(keys.planner_status(m, p), encode(self._status()), encoding=_JSON)
            query.drop()
        elif kind == "world":
            query.reply(keys.world(m, p), encode(self.world.snapshot(self.clock())), encoding=_JSON)
            query.drop()
        elif len(self._pending) >= self.cfg.preview_queue:
            _Answer(query, 0.0).error(ErrorReply(error="planner busy: too many previews queued"))
        else:
            key = str(query.key_expr)
            answer = _Answer(query, t_recv + self.cfg.preview_budget_ms / 1e3)
            try:
                uid = keys.parse(key).id
            except InputError as err:
                answer.error(ErrorReply.of(err))
                return
            if not self.world.owns(uid):  # scale-out: the unit's owner answers, once; what-ifs too
                query.drop()
                return
            view = self.world.view(uid)
            self._pending[id(answer)] = answer
            heapq.heappush(self._deadlines, (answer.deadline, id(answer), answer))
            payload = query.payload.to_bytes() if query.payload is not None else b""
            self._previewers.submit(self._preview, answer, key, view, payload)

    def _expire_previews(self, now: float) -> None:
        """Answer every preview past its deadline with ``expired``, computed or not (a stuck one included)."""
        while self._deadlines and self._deadlines[0][0] + EXPIRY_GRACE_S <= now:
            _, ident, answer = heapq.heappop(self._deadlines)
            self._pending.pop(ident, None)
            answer.error(ErrorReply(error="expired: the preview's deadline passed before it was computed"))

    def _preview(self, answer: _Answer, key: str, view: Any, payload: bytes) -> None:
        try:
            left = answer.deadline - self.clock()
            if left <= 0 or answer.done:
                answer.error(ErrorReply(error="expired: the preview's deadline passed in the queue"))
                return
            request = decode_preview_request(payload, self.cfg.bounds, self._origin)
            result = preview(view, request, self.clock, 0.9 * left, self.cfg.preview_max_iter)
            if request.geojson:
                body = geojson.preview_reply(
                    self._origin, result, view.threats, result.path[0], result.path[-1]
                )
            else:
                body = fit_reply(result)
            answer.reply(key, body)
        except InputError as err:
            answer.error(ErrorReply.of(err))
        except Exception:
            log.exception("preview failed", extra={"fields": {"key": key}})
            answer.error(ErrorReply(error="internal error while previewing", field="$"))

    def _status(self) -> PlannerStatus:
        p50, p99 = self.latency.quantiles_ms()
        c = self.world.counts()
        return PlannerStatus(
            planner=self.cfg.planner_id,
            mission=self.cfg.mission,
            version=__version__,
            uptime_s=max(self.clock() - self.started, 0.0),
            units=c["units"],
            units_stale=c["units_stale"],
            threats=c["threats"],
            msgs_in=self.counters["msgs_in"],
            msgs_out=self.counters["msgs_out"],
            rejected=c["rejected"],
            latency_p50_ms=p50,
            latency_p99_ms=p99,
            deliberating=c["deliberating"],
            units_owned=c["units_owned"],
            overload=c["overload"] + self.counters["overload"],
            pushes=c["pushes"],
            pushes_resent=c["pushes_resent"],
        )
