"""Twins: another planner session serving this mission under this planner's own id.

Both hold the same ``alive/planner/{id}`` token, so liveliness cannot tell
them apart, but each status names its session.  ``watch_twins`` asks every
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
from pfp_service.wire import keys
from pfp_service.wire.messages import decode_planner_status

__all__ = ["PEERS_EVERY_S", "PEER_MISSES", "watch_twins"]

PEERS_EVERY_S = 1.0  # every planner of the mission is asked for its status this often (same-id peers)
PEER_MISSES = 5  # a same-id peer that missed this many asks in a row is gone (a busy loop answers late)


def watch_twins(
    session: zenoh.Session,
    mission: str,
    planner_id: str,
    zid: str,
    stop: threading.Event,
    twin: Callable[[str, bool], None],
) -> None:
    """Until ``stop``: call ``twin(session id, True)`` when a twin appears and ``(.., False)`` when it goes."""
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
