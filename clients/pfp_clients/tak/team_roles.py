"""What TAK shows of teams: each member's team and roles, for its marker's remarks (sans-I/O).

The bridge hears ``team/{t}`` puts and deletes (``on_team``); a unit's marker
then carries ``team alpha: lead, robot`` in its remarks (``remark``), at its
next direction or refresh.  A team that cannot be decoded is ignored, with a
line to the log: the planner refuses it on its key with the reason.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.wire import messages as m

__all__ = ["TeamRoles", "thin"]


class TeamRoles:
    """The teams heard on Zenoh, and each member's ``team X: roles`` remark."""

    def __init__(self, log: Callable[[str], None] = lambda _m: None) -> None:
        self.log = log
        self.teams: dict[str, m.TeamUpdate] = {}

    def on_team(self, key: str, payload: bytes | None) -> None:
        """A team put (``payload``) or dissolved (``None``)."""
        tid = keys.parse(key).id
        if payload is None:
            self.teams.pop(tid, None)
            return
        try:
            self.teams[tid] = m.decode_team(payload)
        except InputError as exc:
            self.log(f"ignored team {tid}: {exc}")

    def remark(self, unit: str) -> str:
        """``team alpha: lead, robot`` for each team ``unit`` is in (``; `` between teams), or ``""``."""
        said = []
        for tid, team in sorted(self.teams.items()):
            roles = team.roles(unit)
            if roles:
                said.append(f"team {tid}: {', '.join(roles)}")
        return "; ".join(said)


def thin(path: np.ndarray, n: int) -> np.ndarray:
    """At most ``n`` points of ``path``, evenly spread, its ends kept."""
    if len(path) <= n:
        return path
    idx = np.unique(np.round(np.linspace(0, len(path) - 1, n)).astype(int))
    return path[idx]
