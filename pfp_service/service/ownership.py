"""Cluster ownership: which live planner guides a unit (rendezvous hashing), and who is live.

Every planner of a mission takes every goal and threat; each unit is guided
by the one live planner with the highest rendezvous weight for it.  A planner
joining takes about 1/K of each planner's units; one leaving hands over only
its own.  A peer's token going is acted on only once it stays gone for the
debounce (a router restart flaps every token).  Pure values: ``now`` is a
parameter, and the world sets the debounce's timer.
"""

from __future__ import annotations

import hashlib

__all__ = ["Ownership", "rendezvous_weight"]


def rendezvous_weight(unit_id: str, planner: str) -> int:
    """The rendezvous weight of a unit on a planner: stable across processes and restarts."""
    digest = hashlib.blake2b(f"{unit_id}\0{planner}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


class Ownership:
    """The live peers of one planner, and which units it owns among them."""

    def __init__(self, me: str, cluster: bool) -> None:
        self.me = me
        self.cluster = cluster
        self.peers: set[str] = set()
        self.gone: dict[str, float] = {}  # peer -> when its token went, until the debounce ends

    def owns(self, unit_id: str) -> bool:
        """Whether this planner guides ``unit_id``: the highest weight of unit x planner wins.

        Without ``cluster`` it owns every unit.
        """
        if not self.cluster or not self.peers:
            return True
        best = max((*self.peers, self.me), key=lambda p: (rendezvous_weight(unit_id, p), p))
        return best == self.me

    def joined(self, planner: str) -> bool:
        """A peer's token is there: whether it is new (not this planner, not known, not back within the debounce)."""
        if planner == self.me:
            return False
        if self.gone.pop(planner, None) is not None or planner in self.peers:
            return False
        self.peers.add(planner)
        return True

    def left(self, planner: str, now: float) -> bool:
        """A peer's token went: whether its debounce starts now (the world sets a timer for its end)."""
        if planner in self.peers and planner not in self.gone:
            self.gone[planner] = now
            return True
        return False

    def settle(self, planner: str, now: float, debounce_s: float) -> bool:
        """The debounce's timer is due: whether the peer stayed gone, and so is no longer one."""
        since = self.gone.get(planner)
        if since is None or now - since < debounce_s:
            return False
        del self.gone[planner]
        self.peers.discard(planner)
        return True
