"""Sans-I/O bookkeeping of what an observer saw: unit tracks, arrivals and the threats in force.

Times are the observer's seconds (simulated seconds for ``pfp inject``).  A
threat's history is a list of versions, each in force from its put to its
move, removal or TTL; a track segment is judged under the versions in force
when it began, so a pop-up threat counts only from its appearance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pfp_service.core.metrics import Epoch, segment_clearance
from pfp_service.core.threat import Threat, ThreatField
from pfp_service.wire import ThreatUpdate
from pfp_service.world import translate

__all__ = ["ThreatVersion", "Watch"]


@dataclass(frozen=True)
class ThreatVersion:
    """One shape and place of a threat, in force over ``[start_s, end_s)``."""

    threat_id: str
    update: ThreatUpdate
    start_s: float
    end_s: float = math.inf

    def threat(self) -> Threat:
        return translate.threat(self.update, self.threat_id)


@dataclass
class Watch:
    """Tracks, arrivals and threat history, fed by the observer's callbacks' decoded messages."""

    tracks: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    arrived_at_s: dict[str, float] = field(default_factory=dict)
    statuses: dict[str, str] = field(default_factory=dict)
    versions: list[ThreatVersion] = field(default_factory=list)

    # -- units ------------------------------------------------------------------
    def on_state(self, unit: str, position: tuple[float, float], t_s: float) -> None:
        self.tracks.setdefault(unit, []).append((t_s, float(position[0]), float(position[1])))

    def position(self, unit: str) -> tuple[float, float] | None:
        tr = self.tracks.get(unit)
        return (tr[-1][1], tr[-1][2]) if tr else None

    def on_status(self, unit: str, status: str, t_s: float) -> None:
        """A direction's status: ``arrived`` marks arrival, anything else revokes it."""
        self.statuses[unit] = status
        if status == "arrived":
            self.arrived_at_s.setdefault(unit, t_s)
        else:
            self.arrived_at_s.pop(unit, None)

    def on_arrived_event(self, unit: str, t_s: float) -> None:
        self.arrived_at_s.setdefault(unit, t_s)

    # -- threats ----------------------------------------------------------------
    def _close(self, threat_id: str, t_s: float) -> ThreatVersion | None:
        for i, v in enumerate(self.versions):
            if v.threat_id == threat_id and v.end_s > t_s:
                self.versions[i] = ThreatVersion(v.threat_id, v.update, v.start_s, t_s)
                return v
        return None

    def threat_put(self, threat_id: str, update: ThreatUpdate, t_s: float) -> None:
        self._close(threat_id, t_s)
        end = t_s + update.ttl_s if update.ttl_s is not None else math.inf
        self.versions.append(ThreatVersion(threat_id, update, t_s, end))

    def threat_removed(self, threat_id: str, t_s: float) -> None:
        self._close(threat_id, t_s)

    def current(self, threat_id: str) -> ThreatVersion | None:
        live = [v for v in self.versions if v.threat_id == threat_id and v.end_s == math.inf]
        return live[-1] if live else None

    def in_force(self, t_s: float, only: str | None = None) -> list[ThreatVersion]:
        return [
            v for v in self.versions if v.start_s <= t_s < v.end_s and (only is None or v.threat_id == only)
        ]

    # -- judgement ----------------------------------------------------------------
    def epochs(
        self, times_s: list[float], intensity: str, only: str | None = None
    ) -> list[tuple[Epoch, list[ThreatVersion]]]:
        """Runs of consecutive segments (segment i starts at ``times_s[i]``) under the same threats."""
        out: list[tuple[Epoch, list[ThreatVersion]]] = []
        n_seg = max(len(times_s) - 1, 0)
        i = 0
        while i < n_seg:
            force = self.in_force(times_s[i], only)
            j = i + 1
            while j < n_seg and self.in_force(times_s[j], only) == force:
                j += 1
            field = ThreatField([v.threat() for v in force], intensity)  # type: ignore[arg-type]
            out.append((Epoch(i, j, field), force))
            i = j
        return out

    def clearance(self, unit: str, to: str | None = None) -> float:
        """Smallest distance from the unit's observed track to a threat in force (inf if none ever was)."""
        tr = self.tracks.get(unit, [])
        if not tr:
            return math.inf
        path = np.array([(x, y) for _t, x, y in tr], dtype=float)
        times = [t for t, _x, _y in tr]
        if len(tr) == 1:
            force = self.in_force(times[0], to)
            pos = np.array([v.update.position for v in force], dtype=float).reshape(-1, 2)
            return segment_clearance(path, pos)
        best = math.inf
        for ep, force in self.epochs(times, "peak", to):
            if not force:
                continue
            pos = np.array([v.update.position for v in force], dtype=float).reshape(-1, 2)
            best = min(best, segment_clearance(path[ep.first : ep.last + 1], pos))
        return best
