"""What one input to the bridge's state machine (``state.BridgeState``) produced, for its driver to do.

CoT for every link or for one, Zenoh puts and deletes, routes to fetch: plain values, so the
state machine stays sans-I/O and the driver (``bridge``) alone sends them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Outputs", "ZenohDelete", "ZenohPut"]


@dataclass(frozen=True, slots=True)
class ZenohPut:
    key: str
    payload: bytes


@dataclass(frozen=True, slots=True)
class ZenohDelete:
    key: str


@dataclass
class Outputs:
    """What one input produced: CoT for every link, CoT for one link (``(link, bytes)``), Zenoh actions, routes to fetch."""

    cot: list[bytes] = field(default_factory=list)
    zenoh: list[ZenohPut | ZenohDelete] = field(default_factory=list)
    routes: list[str] = field(default_factory=list)
    to_link: list[tuple[str, bytes]] = field(default_factory=list)

    def extend(self, other: Outputs) -> None:
        self.cot += other.cot
        self.zenoh += other.zenoh
        self.routes += other.routes
        self.to_link += other.to_link
