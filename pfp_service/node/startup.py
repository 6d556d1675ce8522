"""What a planner holds before its first tick: its store restored, its ``--zones`` file, its peers' world.

``PlannerNode.start`` calls these in order, after every subscriber and
queryable is declared (a write from then on waits for the loop, and is the
newer) and before its liveliness token says it is ready.  Each applies what
it brings to the world at once, with the collector paused as a tick's
``apply`` is (``gcpause``).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import zenoh

from pfp_service.node import gcpause
from pfp_service.node.config import ServeConfig
from pfp_service.node.log import get_logger
from pfp_service.node.staterows import Restored
from pfp_service.node.store import Store
from pfp_service.node.worldpages import fetch_world
from pfp_service.node.writes import Writes
from pfp_service.wire import RestoredEvent
from pfp_service.world.events import Input, zone_put
from pfp_service.world.world import World

__all__ = ["join", "restore", "restored_event"]

log = get_logger("node")


def restore(
    world: World, store: Store | None, writes: Writes, cfg: ServeConfig, clock: Callable[[], float]
) -> Restored | None:
    """The store's goals, threats, zones and the rest applied, then the ``--zones`` file (stored too)."""
    restored = None
    if store is not None:
        restored = store.restore(time.time())
        writes.order.load(restored.order)  # an older write asked again stays superseded
        with gcpause.paused():
            world.apply(restored.inputs, clock())
    if cfg.zones is not None:  # the --zones file: in force (and stored) before the first state
        from pfp_service.geojson import load_zones

        filed: list[Input] = [zone_put(z) for z in load_zones(cfg.zones, cfg.origin)]
        if store is not None:
            filed = store.commit_batch(filed, time.time(), cfg.threat_ttl_s, cfg.mission)
        with gcpause.paused():
            world.apply(filed, clock())
    return restored


def restored_event(restored: Restored, planner: str) -> RestoredEvent:
    """The ``restored`` event: what came back from the store, counted by kind."""
    return RestoredEvent.counted(
        restored.kept,
        planner=planner,
        missions=restored.missions,
        expired=restored.expired,
        corrupt=restored.corrupt,
        set_aside=restored.set_aside,
    )


def join(session: zenoh.Session, world: World, cfg: ServeConfig, clock: Callable[[], float]) -> None:
    """Apply what the planners already serving the mission hold, every page of it (none: ~1 ms)."""

    def ask(selector: str, timeout_s: float) -> list[bytes]:
        # other sessions only: our own world queryable, declared already, is not answered before the
        # loop starts, so asking it too cost the whole page timeout (2 s) at every start
        replies = session.get(selector, timeout=timeout_s, allowed_destination=zenoh.Locality.REMOTE)
        return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]

    joined = fetch_world(ask, cfg.mission, cfg.planner_id)
    if joined.inputs:
        with gcpause.paused():
            world.apply(joined.inputs, clock())
    if joined.peers:
        level = log.info if joined.complete else log.warning
        level("joined the mission's planners", extra={"fields": joined.fields()})
