"""Twins: another planner session serving this mission under this planner's own id.

Both hold the same ``alive/planner/{id}`` token, so liveliness cannot tell
them apart, but each status names its session.  ``watch_duplicates`` asks every
planner of the mission for its status each ``PEERS_EVERY_S`` on its own
thread (it blocks on queries, which no callback may) and says when a twin
appears (``alive``) and when one has missed ``PEER_MISSES`` asks in a row.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable

import zenoh

from pfp_service.errors import InputError
from pfp_service.node.log import get_logger
from pfp_service.wire import keys
from pfp_service.wire.messages import TerrainInfo, decode_planner_status
from pfp_service.world.events import Input, PeerPlanner, PeerTerrain

__all__ = ["PEERS_EVERY_S", "PEERS_KNOWN_S", "PEER_MISSES", "Peers", "watch_duplicates"]

PEERS_EVERY_S = 1.0  # every planner of the mission is asked for its status this often (same-id peers)
PEER_MISSES = 5  # a same-id peer that missed this many asks in a row is gone (a busy loop answers late)
PEERS_KNOWN_S = 2.0  # under --cluster, start-up waits this long at most for the live planners' tokens


def watch_duplicates(
    session: zenoh.Session,
    mission: str,
    planner_id: str,
    zid: str,
    stop: threading.Event,
    twin: Callable[[str, bool], None],
    terrain: Callable[[str, TerrainInfo | None], None] | None = None,
) -> None:
    """Until ``stop``: call ``twin(session id, True)`` when a twin appears and ``(.., False)`` when it goes,
    and ``terrain(planner, its TerrainInfo)`` for every other planner of the mission that answers."""
    selector = keys.planner_statuses(mission)
    missed: dict[str, int] = {}  # twins' sessions -> asks missed in a row
    while not stop.wait(PEERS_EVERY_S):
        seen: set[str] = set()
        try:
            replies = session.get(selector, consolidation=zenoh.ConsolidationMode.NONE, timeout=PEERS_EVERY_S)
            for reply in replies:
                if reply.ok is None:
                    continue
                with contextlib.suppress(InputError):
                    st = decode_planner_status(reply.ok.payload.to_bytes())
                    if st.planner == planner_id and st.session and st.session != zid:
                        seen.add(st.session)
                    elif st.planner != planner_id and terrain is not None:
                        terrain(st.planner, st.terrain)
        except Exception:  # the session is closing under us
            if stop.is_set():
                return
            continue
        for other in seen - missed.keys():
            missed[other] = 0
            twin(other, True)
        for other in list(missed):
            missed[other] = 0 if other in seen else missed[other] + 1
            if missed[other] >= PEER_MISSES:
                del missed[other]
                twin(other, False)


log = get_logger("node")  # what the node said about its peers before they had a module


class Peers:
    """The mission's other planners as this one sees them, for the node.

    Their liveliness tokens become ``PeerPlanner`` inputs (the world shares units by them under
    ``--cluster``), and so do twins: a planner answering this one's units too (another id without
    ``--cluster``, or this id from another session: ``watch_duplicates``, its ``PeerPlanner`` naming
    the session).  Twins are listed in the status (``twins``); whether one is a conflict is the
    world's to decide (``world.cluster``).  Called from Zenoh's threads and the twins' watcher;
    the node's ``lock`` guards what they share with the loop.
    """

    def __init__(
        self,
        mission: str,
        planner_id: str,
        cluster: bool,
        lock: threading.Lock,
        push: Callable[[Input], None],
    ) -> None:
        self._mission = mission
        self._planner_id = planner_id
        self._cluster = cluster
        self._lock = lock
        self._push = push
        self._duplicates: set[str] = set()  # planners answering this one's units too (PlannerStatus.twins)
        self.terrain: TerrainInfo | None = None  # this planner's (``node.terrain.terrain_info``)
        self._grounds: dict[str, str | None] = {}  # peers' terrain hashes, as last told to the world

    def on_token(self, sample: zenoh.Sample) -> None:
        """A planner's liveliness token came or went."""
        try:
            pid = keys.parse(str(sample.key_expr)).id
        except InputError:
            return
        alive = sample.kind == zenoh.SampleKind.PUT
        if not self._cluster and pid != self._planner_id:  # not a peer but a twin: both guide every unit
            self._duplicated(pid, alive)
        self._push(PeerPlanner(pid, alive))

    def ask(self, session: zenoh.Session) -> None:
        """Enqueue a ``PeerPlanner`` for each live planner of the mission, once its token has answered.

        A liveliness query ends when every live token has answered (or at
        ``PEERS_KNOWN_S``): start-up waits on that, not on a guess of how long
        the subscriber's history takes.  The subscriber says the same again;
        the world counts a peer once.
        """
        try:
            for reply in session.liveliness().get(keys.alive_planners(self._mission), timeout=PEERS_KNOWN_S):
                if reply.ok is not None:
                    self.on_token(reply.ok)
        except Exception as exc:  # the session is closing under us: the subscriber names them in time
            log.warning("peers not asked", extra={"fields": {"reason": str(exc)[:200]}})

    def on_duplicate(self, zid: str, alive: bool) -> None:
        """``watch_duplicates``: a session serving this planner's id appeared or went."""
        name = f"{self._planner_id[:50]}-{zid[:12]}"
        self._duplicated(name, alive)
        self._push(PeerPlanner(name, alive, session=zid))

    def on_terrain(self, planner: str, theirs: TerrainInfo | None) -> None:
        """``watch_duplicates``: planner ``planner`` of the mission plans over ``theirs``: the world is told
        (``PeerTerrain``) each time it changes, and decides whether it is a conflict."""
        its = theirs.sha256 if theirs is not None else None
        if self._grounds.get(planner, "") == its:
            return
        self._grounds[planner] = its
        self._push(PeerTerrain(planner, theirs, self.terrain))

    def duplicates(self) -> tuple[str, ...]:
        """The twins now, sorted, at most 64 (``PlannerStatus.twins``)."""
        with self._lock:  # the callbacks' threads change them
            return tuple(sorted(self._duplicates))[:64]

    def _duplicated(self, name: str, alive: bool) -> None:
        with self._lock:
            if alive:
                self._duplicates.add(name)
            else:
                self._duplicates.discard(name)
