"""The Zenoh wiring of the planner: decode, enqueue, ``world.apply``, publish.

* Unit states, the flood, wake no Python thread per state: Zenoh keeps them in
  rings the loop drains (``rings.StateRings``: one on the plain key, one per
  shard this planner owns, all on one while it owns them all), latest-wins per unit.
* Ticks amortise: the loop ticks at most every ``MIN_TICK_S`` while states keep coming, so the per-tick
  cost is shared (a wave's shares wait for no pause); idle, it sleeps until a ring's waiter or an
  input wakes it or the world's next deadline comes: no polling, no period.
* Under ``--cluster`` the planner subscribes to the states of its own shards
  only (``World.shards``, rendezvous hashing); as they change, the new rings
  are declared before the old go.
* Callbacks for the rest decode and enqueue, nothing more: everything in
  order, queries handed to the loop.  No callback replies or puts.  Goal,
  threat and zone writes (plain puts and acknowledged writes) are
  ``writes.Writes``'.
* Every subscriber and queryable is declared the moment the session opens,
  the planner's liveliness token last: the token is its readiness
  (docs/wire.md), and a write from then on is held for the loop.
* One planning loop applies a bounded slice of it and a ``Tick`` to the
  ``World`` and publishes what it returns.  Every decision is the world's.
  Directions go out batched by Zenoh, not express: a fifth of the cost per
  put, and no bursts lost from the transmit queue.
* Deliberation jobs the world asks for run in worker processes (``Deliberators``) and come back as
  ``Deliberated`` inputs; previews run on another pool, each with a deadline: neither holds up the loop.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import math
import sys
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar, assert_never

import zenoh

from pfp_service.errors import InputError
from pfp_service.node import gcpause
from pfp_service.node.config import ServeConfig
from pfp_service.node.deliberation import Deliberators
from pfp_service.node.duplicates import Peers, watch_duplicates
from pfp_service.node.log import get_logger, log_changes
from pfp_service.node.loopstats import Latency, LoopTrace, Trim, demote_native_threads
from pfp_service.node.previews import PreviewService, preview_service, warm_once
from pfp_service.node.publish import EVENT_LOG_LINES, Publisher
from pfp_service.node.rings import StateRings
from pfp_service.node.shutdown import join_within, run_steps
from pfp_service.node.startup import join, restore, restored_event
from pfp_service.node.status import planner_status
from pfp_service.node.store import Store
from pfp_service.node.terrain import Sights, terrain_info
from pfp_service.node.worldpages import answer_world
from pfp_service.node.writes import Writes
from pfp_service.wire import (
    ErrorReply,
    ForgottenEvent,
    PlannerStatus,
    UnitState,
    encode,
    keys,
)
from pfp_service.world.events import Input, InputRejected, Outputs, StateReported, Tick, mission_message
from pfp_service.world.intake import Intake
from pfp_service.world.kinds import KINDS, Kind, decode_state
from pfp_service.world.world import World

__all__ = ["PlannerNode"]

log = get_logger("node")
_JSON = zenoh.Encoding.APPLICATION_JSON
SWITCH_INTERVAL_S = 0.0005  # the GIL is handed over this often, so pool threads cannot hold up the loop
QUERIES_MAX = 4096  # status, world and preview queries waiting for the loop; more are shed
INBOX_MAX = 100_000  # queued inputs beyond this are refused and counted (positions are latest-wins anyway)
MIN_TICK_S = 0.002  # ticks at most this often while states come (measured: docs/operations.md)
TICK_UNITS = 256  # unit reports applied per tick at most (about 5 ms of world and publishing); the rest wait
TICK_INPUTS = 256  # goals, threats and the rest applied per tick at most
DEMOTE_EVERY_S = 5.0  # Zenoh's threads are put under SCHED_BATCH this often (threads it starts later too)
KEY_CACHE = 16_384  # state key -> unit id, unit id -> direction key, remembered; past it, forgotten at once
_V = TypeVar("_V")


def _remembered(cache: dict[str, _V], key: str, make: Callable[[str], _V]) -> _V:
    """``make(key)``, kept in ``cache``; a full cache (``KEY_CACHE``) is forgotten at once, not evicted piecemeal."""
    value = cache.get(key)
    if value is None:
        value = make(key)
        if len(cache) >= KEY_CACHE:
            cache.clear()
        cache[key] = value
    return value


class PlannerNode:
    """One planner of one mission on an open Zenoh session.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        cfg: the service configuration.
        clock: monotonic seconds; the world sees only this.
        store: durable state (``Store``); goals and threats are committed to it
            before they are applied, and restored from it at ``start``.
        previews: the preview service made by ``preview_service`` before the session opened, so its workers
            warm up while a client-mode planner waits for its router; the node shuts it down (or makes one).
    """

    def __init__(
        self,
        session: zenoh.Session,
        cfg: ServeConfig,
        clock: Callable[[], float] = time.monotonic,
        store: Store | None = None,
        previews: PreviewService | None = None,
    ) -> None:
        self.session = session
        self.store = store
        self._origin = cfg.origin
        self.cfg = cfg
        self.clock = clock
        self.world = World(cfg.world_settings())
        self.started = clock()
        self.counters = {"msgs_in": 0, "msgs_out": 0}
        self._out = Publisher(session, cfg.mission, self.counters)  # directions, events and other puts
        self.latency = Latency()
        self._lock = threading.Lock()
        self._intake = Intake(INBOX_MAX, TICK_INPUTS, TICK_UNITS)  # inputs and states, for the loop
        self.zid = str(session.info.zid())
        self._queries: collections.deque[tuple[str, zenoh.Query, float]] = collections.deque()
        self._wake = threading.Event()
        self._stop = threading.Event()
        # goals, threats and zones: puts and acknowledged-write queries, waiting for the loop (writes.py)
        self._writes = Writes(cfg, self.zid, self._lock, self._wake.set, self._intake.refused)
        # the mission's other planners: peers' tokens for the world, twins for the status and their conflict
        self._peers = Peers(cfg.mission, cfg.planner_id, cfg.cluster, self._lock, self._push)
        self._peers.terrain = terrain_info(cfg)  # a peer over another DEM is a conflict (the world's say)
        self._declared: list[Any] = []
        self._loop_thread: threading.Thread | None = None
        self._trim = Trim()
        self._trace = LoopTrace(cfg.loop_trace, clock)  # off unless configured
        self._state_keys = keys.KeyOf(keys.KeyKind.UNIT_STATE, cfg.mission)
        self._rings = StateRings(session, self._lock, self._wake, self._stop)
        self._shards: frozenset[int] = frozenset()
        self._direction_keys = keys.KeyOf(keys.KeyKind.UNIT_DIRECTION, cfg.mission)
        # a unit's keys parsed or built once (a shard's state key took the full parse, ~5 us a state)
        self._uid_of: dict[str, str] = {}
        self._direction_of: dict[str, zenoh.KeyExpr] = {}
        self._deliberators = Deliberators(cfg.deliberation_workers, clock, self._push)
        self._sights = Sights(self.world.settings.terrain, self._push)  # threats' windows, off the loop
        self._previews = previews if previews is not None else preview_service(cfg, clock)

    # -- lifecycle --------------------------------------------------------------
    def start(self) -> None:
        """Listen first, then warm up, restore and join; the planner's token says it is ready.

        Every subscriber and queryable is declared before anything slow (the
        workers' warm-up, the store, the peers): a state, goal or threat that
        reaches the router from then on is held for the loop, not lost, and
        restored goals are applied before it (the live write is the newer).
        The liveliness token ``alive/planner/{id}`` comes last: a client that
        waits for it knows its writes are taken (docs/wire.md, readiness).
        """
        m, p = self.cfg.mission, self.cfg.planner_id
        s = self.session
        self._listen(s)
        # Python threads (previews, deliberation) take the GIL for 5 ms at a time by default, which
        # the loop's p99 pays (docs/operations.md, "Figures behind the code's choices").
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        warm_once(self.world.settings)  # a no-op where the fork server's warm-up ran
        self._previews.wait_ready()  # the deliberation workers warm up meanwhile; jobs wait for them
        restored = restore(self.world, self.store, self._writes, self.cfg, self.clock)
        join(s, self.world, self.cfg, self.clock)
        if self.cfg.cluster:  # the peers named before the first direction, so no unit is guided twice
            self._peers.ask(s)
        self._declared.append(s.liveliness().declare_token(keys.alive_planner(m, p)))
        if restored is not None:
            self._out.event(restored_event(restored, p), collections.Counter())
        self._loop_thread = threading.Thread(target=self._loop, name="pfp-plan", daemon=True)
        self._loop_thread.start()
        twins = (s, m, p, self.zid, self._stop, self._peers.on_duplicate, self._peers.on_terrain)
        self._duplicates_thread = threading.Thread(
            target=watch_duplicates, args=twins, name="pfp-duplicates", daemon=True
        )
        self._duplicates_thread.start()
        log.info("planner ready", extra={"fields": {"mission": m, "planner": p, "session": self.zid}})

    def _listen(self, s: zenoh.Session) -> None:
        """Declare every subscriber and queryable; their callbacks only enqueue, so the loop need not run yet.

        Each input kind's subscriptions come from its entry (``world.kinds.KINDS``, in its order:
        the writes first, since a lost goal stays lost and a lost state is followed by the unit's
        next report), wired as its mode says (``_wire``); then the queryables.
        """
        m, p = self.cfg.mission, self.cfg.planner_id
        for kind in KINDS:
            self._declared += self._wire(s, kind)
        self._declared += [
            s.declare_queryable(keys.previews(m), lambda q: self._on_query("preview", q)),
            s.declare_queryable(keys.team_previews(m), lambda q: self._on_query("team", q)),
            s.declare_queryable(keys.planner_status(m, p), lambda q: self._on_query("status", q)),
            s.declare_queryable(keys.world(m, p), lambda q: self._on_query("world", q)),
        ]
        log.info("listening", extra={"fields": {"mission": m, "planner": p}})

    def _wire(self, s: zenoh.Session, kind: Kind) -> list[Any]:
        """One input kind's subscriptions, as its mode (``world.kinds.Mode``) says it is read."""
        m = self.cfg.mission
        match kind.mode:
            case "write":  # plain puts and acknowledged writes, one generic handler (writes.py)
                return self._writes.declare(s, m, kind)
            case "state":
                # in rings Zenoh keeps (no Python thread, no GIL per sample), which the loop drains: the
                # latest STATE_RING states, older ones dropped first under a flood; and this planner's shards
                self._rings.add("plain", kind.wildcard(m))
                self._sync_shards()
                return []
            case "token":  # a unit's token: its input made from the id and whether it came or went
                on = functools.partial(self._on_token, kind, keys.KeyOf(kind.key, m))
                return [s.liveliness().declare_subscriber(kind.wildcard(m), on, history=True)]
            case "peers":  # the mission's planners: peers for the world, twins for the status (twins.py)
                return [
                    s.liveliness().declare_subscriber(kind.wildcard(m), self._peers.on_token, history=True)
                ]
            case (
                "shared"
            ):  # what planners share: read only under --cluster, where another may take a unit over
                if not self.cfg.cluster:
                    return []
                on = functools.partial(self._on_shared, kind, keys.KeyOf(kind.key, m))
                return [s.declare_subscriber(kind.wildcard(m), on)]
            case _:
                assert_never(kind.mode)

    def stop(self) -> None:
        """Stop the loop and the pools, a step at a time (``shutdown.run_steps``: a slow step is named)."""
        self._stop.set()
        self._wake.set()
        loop, twins = self._loop_thread, getattr(self, "_duplicates_thread", None)
        run_steps(
            [
                ("loop", lambda: join_within(loop, 2.0)),
                ("rings", self._drain_rings),
                ("duplicates", lambda: join_within(twins, 2.0)),
                ("deliberators", self._deliberators.shutdown),
                ("sights", self._sights.shutdown),
                ("previews", self._previews.shutdown),
                ("trace", self._trace.close),
                ("undeclare", self._undeclare),
            ],
            log,
        )

    def _drain_rings(self) -> None:
        for name in self._rings.names():
            self._states(self._rings.remove(name), self.clock())

    def _undeclare(self) -> None:
        for d in self._declared:
            with contextlib.suppress(Exception):  # already gone with the session: nothing to release
                d.undeclare()
        self._declared.clear()

    # -- callbacks: decode and enqueue, nothing more -----------------------------
    def _push(self, item: Input) -> None:
        with self._lock:
            taken = self._intake.put(item)
        if taken:
            self._wake.set()

    def _state(self, sample: zenoh.Sample) -> tuple[str, UnitState] | None:
        """One state from a ring (the loop thread), decoded; ``None``: rejected (an event says why)."""
        key, kind = str(sample.key_expr), None  # the key's kind, once the key itself parsed
        try:
            uid = _remembered(self._uid_of, key, self._state_keys.id)
            kind = keys.KeyKind.UNIT_STATE
            return uid, decode_state(sample.payload.to_bytes(), self.cfg.bounds, self._origin)
        except InputError as err:
            self._push(InputRejected(key, err, kind))
            return None

    def _states(self, samples: list[Any], received: float) -> None:
        """States from the rings, decoded and queued latest-wins per unit, under one lock."""
        got = [st for sample in samples if (st := self._state(sample)) is not None]
        with self._lock:
            for uid, msg in got:
                self._intake.state(uid, msg, received)

    def _direction_key(self, unit: str) -> zenoh.KeyExpr:
        return _remembered(self._direction_of, unit, lambda u: zenoh.KeyExpr(self._direction_keys.key(u)))

    def _on_token(self, kind: Kind, ids: keys.KeyOf, sample: zenoh.Sample) -> None:
        try:
            uid = ids.id(str(sample.key_expr))
        except InputError:
            return
        self._push(kind.put(uid, sample.kind == zenoh.SampleKind.PUT))

    def _on_shared(self, kind: Kind, ids: keys.KeyOf, sample: zenoh.Sample) -> None:
        key, known = str(sample.key_expr), None  # the key's kind, once the key itself parsed
        try:
            uid, known = ids.id(key), kind.key
            if sample.kind == zenoh.SampleKind.PUT:
                self._push(kind.make(uid, False, sample.payload.to_bytes(), None, None))
        except InputError as err:
            self._push(InputRejected(key, err, known))

    def _on_query(self, kind: str, query: zenoh.Query) -> None:
        with self._lock:
            if len(self._queries) >= QUERIES_MAX:  # a query flood: shed, counted, never queued unbounded
                self._intake.refused()
                query.drop()  # type: ignore[no-untyped-call]  # zenoh stub
                return
            self._queries.append((kind, query, self.clock()))
        self._wake.set()

    # -- state rings: the plain key and this planner's shards ------------------------------
    def _sync_shards(self) -> None:
        """Subscribe to the shards the world says this planner owns; new rings first, then the old go."""
        shards = self.world.shards()
        if shards == self._shards:
            return
        m = self.cfg.mission
        want = {"all": keys.sharded_states(m)} if len(shards) == keys.SHARDS else {}
        want = want or {str(n): keys.shard_states(m, n) for n in sorted(shards)}
        for name, key in want.items():
            if name not in self._rings.names():
                self._rings.add(name, key)
        for name in [n for n in self._rings.names() if n != "plain" and n not in want]:
            self._states(self._rings.remove(name), self.clock())  # what it held still counts
        log.info("state shards", extra={"fields": {"shards": sorted(shards)}})
        self._shards = shards

    # -- the planning loop ------------------------------------------------------------
    def _drain_states(self) -> int:
        """Decode what the rings hold (at most ``STATE_RING`` each), latest-wins per unit."""
        now = self.clock()
        samples = self._rings.drain()
        if samples:
            self._states(samples, now)
        return len(samples)

    def _loop(self) -> None:
        """Tick at most every ``MIN_TICK_S`` while states come; idle, sleep until woken or due (no polling)."""
        last = -math.inf
        idle = False
        demoted = -math.inf
        while not self._stop.is_set():
            if self.clock() - demoted >= DEMOTE_EVERY_S:
                demote_native_threads()  # Zenoh's threads (new ones too) no longer preempt a tick
                demoted = self.clock()
            due = self._due(last)
            if idle:  # nothing came: the waiters watch the rings, the wake event the rest
                self._rings.arm()
                self._wake.wait(None if due is None else max(due - self.clock(), 0.0))
            pause = last + MIN_TICK_S - self.clock()
            if pause > 0 and not self.world.directions_owed():  # amortise; a wave's shares (not points) go on
                time.sleep(pause)
            woke = self._wake.is_set()
            self._wake.clear()
            t0 = self.clock()
            got = self._drain_states()
            idle = not got
            now = self.clock()
            if self._trace.on:
                self._trace.part("drain", now - t0)
            if not (woke or got or (due is not None and now >= due)):
                continue
            last = now
            try:
                self._tick()
                self._sync_shards()
            except Exception:  # never let one bad batch kill the planner; say so loudly
                log.exception("planning loop error")
                time.sleep(MIN_TICK_S)  # and never spin: a wave's owed shares skip the pause above

    def _due(self, last: float) -> float | None:
        """When to tick if nothing comes: the world's deadline, or ``tick_s`` on while the node's work waits."""
        due = self.world.next_deadline()
        if self._previews.waiting() or self._deliberators.waiting() or self._trim.waiting():
            return last + self.cfg.tick_s if due is None else min(due, last + self.cfg.tick_s)
        return due

    def _tick(self) -> None:
        with self._lock:  # a bounded slice: a storm is spread over ticks, so no tick holds up the rest
            got = self._intake.take()
            inbox, states = got.inputs, got.states
            queries, self._queries = self._queries, collections.deque()
            writes = self._writes.take(TICK_INPUTS)
            if got.more or self._writes.waiting():
                self._wake.set()  # the rest at once, in the next tick
        now = self.clock()
        acks = self._writes.admit(writes, inbox)
        batch: list[Input] = list(inbox)
        batch += [StateReported(uid, msg) for uid, (msg, _t) in states.items()]
        batch.append(Tick(now, got.shed))
        self.counters["msgs_in"] += len(batch) - 1
        refused = None
        if self.store is not None:  # applied only once committed, with the write order it makes
            batch, refused = self.store.commit_writes(
                batch, time.time(), self.cfg.threat_ttl_s, self.cfg.mission, self._writes.order.batch_rows()
            )
        self._writes.order.settle(refused is None)  # the order is never ahead of the store
        log_changes(log, inbox)
        tr = self._trace
        t_apply = self.clock()
        # a wave owed: its share gets an apply of its own once this batch's directions are out, so a state
        # waits for one share at most, not for the share steered in its own tick (BENCHMARKS.md, issue 32)
        wave, shared_s = self.world.wave_pending(), 0.0
        with gcpause.paused():  # the collector runs once the directions are out (gcpause)
            # a wave's share: what the apply affords in the loop thread's CPU (``wave.Budget``), preemption aside
            out = self.world.apply(batch, now, time.thread_time, share=not wave)
            t_applied = self.clock()
            self._writes.acknowledge(acks, refused)
            self._keep(out, now)
            self._out.directions(out.directions, self._direction_key, tr, self.clock)
            if wave:
                t_share = self.clock()
                share = self.world.apply([], t_share, time.thread_time)
                shared_s = self.clock() - t_share
                self._keep(share, t_share)
                self._out.directions(share.directions, self._direction_key, tr, self.clock)
                out.extend(share)
        t_put = self.clock()
        if self.world.wave_pending():  # a wave went out first: its points and jobs in the next tick, at once
            self._wake.set()
        logged: collections.Counter[str] = collections.Counter()
        for ev in out.events:
            self._out.event(ev, logged)
        for fault in out.faults:  # the world's bulkheads: once a minute per key, never a traceback
            log.error("input failed inside the planner", extra={"fields": fault.fields()})
        for kind, n in logged.items():
            if n > EVENT_LOG_LINES:  # a storm (5,000 units stale at once) is one line, not 5,000
                log.warning("more events", extra={"fields": {"kind": kind, "count": n - EVENT_LOG_LINES}})
        if self.cfg.cluster:
            for rec in out.missions:
                self._out.put(
                    keys.unit_mission(self.cfg.mission, rec.unit),
                    encode(mission_message(rec, self.cfg.planner_id)),
                )
        self._deliberators.cancel(out.cancelled)
        self._deliberators.submit(out.jobs)
        self._sights.submit(out.sights)
        self._sights.build(out.slopes)
        self._deliberators.feed()
        done = self.clock()
        for _msg, t_recv in states.values():
            self.latency.add(done - t_recv)
        for kind, query, t_recv in queries:
            self._answer(kind, query, t_recv)
        self._previews.expire(self.clock())
        if tr.on:
            end = self.clock()
            tr.part("intake", t_apply - now)
            tr.part("apply", t_applied - t_apply)
            tr.part("put", t_put - t_applied - shared_s)
            tr.part("share", shared_s)  # the apply of a wave's share, after the batch's puts
            tr.part("after", done - t_put)
            tr.part("queries", end - done)
            oldest = max((done - t for _m, t in states.values()), default=0.0)
            tr.tick(end - now, len(states), oldest, end)

    def _keep(self, out: Outputs, now: float) -> None:
        """Record ``out``'s missions and forgotten units in the store, and trim once units were forgotten."""
        forgotten = [e.unit for e in out.events if isinstance(e, ForgottenEvent)]
        if self.store is not None and (out.missions or forgotten):
            self.store.record(out.missions, forgotten)
        if forgotten:
            self._trim.forgot(len(forgotten), now)
        self._trim.due(now)

    # -- queries ------------------------------------------------------------------------
    def _answer(self, kind: str, query: zenoh.Query, t_recv: float) -> None:
        m, p = self.cfg.mission, self.cfg.planner_id
        if kind == "status":
            query.reply(keys.planner_status(m, p), encode(self._status()), encoding=_JSON)
            query.drop()  # type: ignore[no-untyped-call]  # zenoh stub
        elif kind == "world":
            answer_world(query, self.world, self.clock(), m, p)
            query.drop()  # type: ignore[no-untyped-call]  # zenoh stub
        elif kind == "team":
            self._previews.team(query, self.world, t_recv)
        else:
            key = str(query.key_expr)
            try:
                uid = keys.parse(key).id
            except InputError as err:
                self._previews.refuse(query, ErrorReply.of(err))
                return
            view = self.world.preview(uid)  # None: another planner answers (scale-out: the owner, once)
            if view is None:
                query.drop()  # type: ignore[no-untyped-call]  # zenoh stub
                return
            self._previews.submit(query, key, view, t_recv)

    def _status(self) -> PlannerStatus:
        uptime_s = max(self.clock() - self.started, 0.0)
        counts, twins = self.world.counts(), self._peers.duplicates()
        return planner_status(self.cfg, counts, self.latency, self.counters, uptime_s, self.zid, twins)
