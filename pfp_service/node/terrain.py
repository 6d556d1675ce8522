"""The planner's terrain, seen from the node: loaded before anything starts, named in the status.

``placed`` loads the DEM of ``ServeConfig.terrain`` (``terrain.live.load``,
once per process) and gives the configuration its origin: the DEM's centre
when none was given, so every position on the wire, the status and the
zones' file share the plane the world plans on.  ``terrain_info`` is the
status's ``TerrainInfo`` (a peer over another DEM is the world's conflict:
``world.cluster.terrain_conflict``).

``Sights`` computes the threats' windows the world asks for
(``Outputs.sights``, ``world.terrain``) off the planning loop: one thread,
started when asked and gone when nothing waits, latest wins per threat (an
ask for a threat put again meanwhile is dropped unrun), each window handed
back to the node's inbox as a ``SightLanded``.  The sweep is compiled
without the GIL (``viewshed._sweep``), so the loop runs on beside it; a
window that fails is logged and never lands, and the world's ``sight``
timer puts its threat in force blind.

``Sights.build`` builds the barrier sets of override slope limits the world
asks for (``Outputs.slopes``, ``world.slopes``), one ask per limit, each
handed back as a ``SlopeLanded`` (a failure too, as a value).  Unlike the
sweep, a set's build holds the GIL for most of its 0.5-1.3 s (rasterio's
polygons, shapely's checks): on a thread beside the loop it would slow the
loop by a third for that second (BENCHMARKS.md).  So a terrain that is passed
by name (``terrain.live.load``'s) is built in a worker process of its own
(``workers.WorkerPool``, one slot, started at the first ask, ``nice`` below
the loop), killed past ``SLOPE_BUILD_S``: a fork of the warm planner holds the
terrain already, a fresh interpreter loads it first; only the set's unpickling (a few
milliseconds) is the loop process's.  A terrain made from a grid in this
process (the tests', the warm-up's) is built on a thread (``answer_slope``),
never on the loop either.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import msgspec

from pfp_service.node.config import ServeConfig
from pfp_service.node.log import get_logger
from pfp_service.node.tasks import Outcome, Task
from pfp_service.wire.messages import TerrainInfo
from pfp_service.world.slopes import SLOPE_WAIT_S
from pfp_service.world.terrain import Ground, SightAsk, SightLanded, SlopeAsk, SlopeLanded, answer_slope
from pfp_service.world.wave import answered

__all__ = ["Sights", "placed", "terrain_info"]

log = get_logger("terrain")
SLOPE_BUILD_S = (
    60.0  # a build (a fresh worker's DEM load with it) is killed past this; the world waits SLOPE_WAIT_S
)
SLOPE_WORKER_MEMORY_MB = 1024.0  # address space the builder may add to its warm size
SLOPE_WORKER_NICE = 5  # below the live loop, as deliberation


def placed(cfg: ServeConfig) -> ServeConfig:
    """``cfg`` with its terrain loaded and its origin the terrain's.

    Raises:
        InputError: the DEM cannot be read, placed, or does not cover the bounds (one line, naming the file).
    """
    if cfg.terrain is None:
        return cfg
    from pfp_service.terrain.live import load

    ground = load(cfg.terrain, cfg.origin, cfg.bounds_tuple(), cfg.terrain_unit)
    return msgspec.structs.replace(cfg, origin=ground.origin)


def terrain_info(cfg: ServeConfig) -> TerrainInfo | None:
    """What ``PlannerStatus.terrain`` says of ``cfg``'s terrain (loaded already: ``placed``)."""
    ground = cfg.world_settings().terrain
    if ground is None:
        return None
    a = ground.about  # type: ignore[attr-defined]
    return TerrainInfo(
        file=a.file[:200],
        sha256=a.sha256,
        south=a.south,
        west=a.west,
        north=a.north,
        east=a.east,
        resolution_m=a.resolution_m,
        unit=a.unit,
        origin_centred=a.centred,
    )


class Sights:
    """The world's asks for threats' windows, computed on one thread off the loop, latest wins."""

    def __init__(self, ground: Ground | None, deliver: Callable[[SightLanded | SlopeLanded], None]) -> None:
        self._ground = ground
        self._deliver = deliver
        self._lock = threading.Lock()
        self._waiting: dict[str, SightAsk] = {}  # by threat: the newest ask only
        self._thread: threading.Thread | None = None
        self._logged_at = 0.0
        self._slopes: dict[int, SlopeAsk] = {}  # by limit: the newest ask only
        self._builder: threading.Thread | None = None
        self._pool: Any = (
            None  # the builder's ``WorkerPool``, made at the first ask of a terrain passed by name
        )

    def submit(self, asks: Sequence[SightAsk]) -> None:
        """Compute ``asks`` off the loop (one waiting for the same threat is replaced)."""
        if not asks or self._ground is None:
            return
        with self._lock:
            for ask in asks:
                self._waiting.pop(ask.threat, None)
                self._waiting[ask.threat] = ask  # at the back: the threats in the order put
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="pfp-sight", daemon=True)
                self._thread.start()

    def build(self, asks: Sequence[SlopeAsk]) -> None:
        """Build the barrier sets ``asks`` want off the loop, on a thread of their own (latest wins per limit)."""
        if not asks or self._ground is None:
            return
        if getattr(self._ground, "key", None):  # passed by name: a worker process builds it
            for ask in asks:
                self._in_worker(ask)
            return
        with self._lock:
            for ask in asks:
                self._slopes.pop(ask.limit, None)
                self._slopes[ask.limit] = ask
            if self._builder is None:
                self._builder = threading.Thread(target=self._build, name="pfp-slope", daemon=True)
                self._builder.start()

    def _in_worker(self, ask: SlopeAsk) -> None:
        from pfp_service.node.workers import WorkerPool

        if self._pool is None:
            self._pool = WorkerPool(
                "slope",
                1,
                memory_mb=SLOPE_WORKER_MEMORY_MB,
                nice=SLOPE_WORKER_NICE,
                on_replaced=lambda why: log.warning("slope worker replaced", extra={"fields": {"why": why}}),
                eager=0,
            )
        start_by = time.monotonic() + SLOPE_WAIT_S  # not started by then the world has given up on it
        task = Task(_build, (self._ground, ask), lambda out: self._built(ask, out), SLOPE_BUILD_S, start_by)
        self._pool.submit(task)

    def _built(self, ask: SlopeAsk, out: Outcome) -> None:
        if out.kind == "done":
            self._slope_landed(ask, out.value)
        else:  # killed past its budget, out of memory, late, or the planner is stopping: a failure
            self._slope_landed(
                ask, SlopeLanded(ask.limit, ask.serial, None, f"{out.kind}: {out.detail}"[:200])
            )

    def _slope_landed(self, ask: SlopeAsk, landed: SlopeLanded) -> None:
        """Hand a set (or its failure, logged: its units stay at the class's) to the node's inbox."""
        if landed.zones is None:
            fields = {"max_slope_deg": ask.limit, "error": landed.error}
            log.error("a slope limit's barriers failed", extra={"fields": fields})
        self._deliver(landed)

    def shutdown(self) -> None:
        """Stop the builder's worker, if one was started (a build in it is killed, not waited for)."""
        if self._pool is not None:
            self._pool.shutdown()

    def idle(self) -> bool:
        """Whether nothing waits or runs (the tests' condition)."""
        with self._lock:
            return self._thread is None and self._builder is None

    def _next(self, waiting: dict[Any, Any], thread: str) -> Any:
        """The oldest ask in ``waiting``; ``None``, with the thread's slot (``thread``) emptied, when none is."""
        with self._lock:
            if not waiting:
                setattr(self, thread, None)
                return None
            return waiting.pop(next(iter(waiting)))

    def _build(self) -> None:
        assert self._ground is not None
        while (ask := self._next(self._slopes, "_builder")) is not None:
            self._slope_landed(ask, answer_slope(self._ground, ask))  # a failure lands too

    def _run(self) -> None:
        assert self._ground is not None
        while (ask := self._next(self._waiting, "_thread")) is not None:
            try:
                landed = answered(self._ground, ask)  # and the reach of its landing (``wave.judge``)
            except Exception as exc:  # never lands: the world's timer puts the threat in force blind
                if time.monotonic() - self._logged_at >= 1.0:
                    self._logged_at = time.monotonic()
                    fields = {"threat": ask.threat, "error": type(exc).__name__, "detail": str(exc)[:200]}
                    log.error("a threat's sight failed", extra={"fields": fields})
                continue
            self._deliver(landed)


def _build(ground: Ground, ask: SlopeAsk) -> SlopeLanded:
    """In the builder's worker: the set ``ask`` wants (``ground`` arrives by name: a fork holds it)."""
    return answer_slope(ground, ask)
