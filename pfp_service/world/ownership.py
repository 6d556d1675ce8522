"""Cluster ownership: which live planner guides a unit (rendezvous hashing of its shard), and who is live.

Every planner of a mission takes every goal and threat; a unit is guided by
the planner owning its shard (``keys.shard_of``), and a planner subscribes
to the states of its own shards only, so K planners each receive about 1/K
of the states.  Shards go by rendezvous hashing with bounded load: shard by
shard, in order, to the live planner with the highest weight for it that
holds fewer than ceil(S/K) yet.  Plain rendezvous over 16 shards left two
planners 10 and 6 shards as often as not; bounded, each has 8, and a planner
joining or leaving still moves few shards besides its own.  A peer's token going is acted on only once it stays gone for the
debounce (a router restart flaps every token).  Pure values: ``now`` is a
parameter, and the world sets the debounce's timer.
"""

from __future__ import annotations

import hashlib
import math

from pfp_service.wire.keys import SHARDS, shard_of

__all__ = ["Ownership", "rendezvous_weight", "shard_owners"]


def rendezvous_weight(unit_id: str, planner: str) -> int:
    """The rendezvous weight of a unit on a planner: stable across processes and restarts."""
    digest = hashlib.blake2b(f"{unit_id}\0{planner}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


def shard_owners(planners: set[str] | frozenset[str], shards: int = SHARDS) -> tuple[str, ...]:
    """The owner of each shard among ``planners``: rendezvous weights, at most ceil(shards/K) each.

    Every planner computes the same from the same set (ties by id).
    """
    ranked = sorted(planners)
    cap = math.ceil(shards / len(ranked))
    load = dict.fromkeys(ranked, 0)
    owners: list[str] = []
    for s in range(shards):
        order = sorted(ranked, key=lambda p: (rendezvous_weight(f"shard-{s}", p), p), reverse=True)
        best = next(p for p in order if load[p] < cap)
        load[best] += 1
        owners.append(best)
    return tuple(owners)


class Ownership:
    """The live peers of one planner, and which units it owns among them."""

    def __init__(self, me: str, cluster: bool) -> None:
        self.me = me
        self.cluster = cluster
        self.peers: set[str] = set()
        self.gone: dict[str, float] = {}  # peer -> when its token went, until the debounce ends
        self._mine: tuple[frozenset[str], frozenset[int]] | None = None  # (peers, my shards) cached

    def shards(self) -> frozenset[int]:
        """The shards this planner owns (every one without ``cluster`` or peers)."""
        if not self.cluster or not self.peers:
            return frozenset(range(SHARDS))
        peers = frozenset(self.peers)
        if self._mine is None or self._mine[0] != peers:
            owners = shard_owners(peers | {self.me})
            self._mine = (peers, frozenset(s for s, p in enumerate(owners) if p == self.me))
        return self._mine[1]

    def owns(self, unit_id: str) -> bool:
        """Whether this planner guides ``unit_id``: it owns the unit's shard.

        Without ``cluster`` it owns every unit.
        """
        if not self.cluster or not self.peers:
            return True
        return shard_of(unit_id) in self.shards()

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
