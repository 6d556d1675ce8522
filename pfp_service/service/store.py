"""Durable state: what users gave the planner survives ``kill -9``.

One SQLite database in WAL mode per mission (``--state-dir``).  It holds the
threats in force (with their absolute expiry, in Unix time, so a restart
honours the time that passed), the goals, and each unit's mission: ``x0``,
the goal and the resolved planner parameters, so a restored unit moves
exactly as it would have.

The node commits a batch's goal and threat inputs *before* it applies them
(``commit_inputs``), so nothing a unit or a reporter saw acknowledged is
lost; missions are derived, and recorded after ``apply`` from the world's
``Outputs.missions``.  ``synchronous=NORMAL`` in WAL mode survives a killed
process (only a power cut can take the last transactions).

No zenoh here, no clock: times are passed in.
"""

from __future__ import annotations

import dataclasses
import json
import sqlite3
from collections.abc import Iterable
from pathlib import Path

import msgspec

from pfp_service.core.params import Resolved
from pfp_service.errors import InputError
from pfp_service.service.events import (
    GoalCancelled,
    GoalSet,
    Input,
    InputRejected,
    MissionRecord,
    MissionRestored,
    ThreatPut,
    ThreatRemoved,
)
from pfp_service.wire import Goal, ThreatUpdate, decode, encode, keys

__all__ = ["Restored", "Store"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS threats (id TEXT PRIMARY KEY, body BLOB NOT NULL, expires_at REAL);
CREATE TABLE IF NOT EXISTS goals (unit TEXT PRIMARY KEY, body BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS missions (
    unit TEXT PRIMARY KEY, epoch INTEGER NOT NULL, origin_x REAL NOT NULL, origin_y REAL NOT NULL, params TEXT NOT NULL
);
"""


@dataclasses.dataclass(frozen=True)
class Restored:
    """What a restart found: inputs to apply, and the counts for the ``restored`` event."""

    inputs: list[Input]
    threats: int
    goals: int
    missions: int
    expired: int


class Store:
    """The planner's durable state in ``directory/state.sqlite3``.

    Raises:
        InputError: the directory cannot be made or the database opened (path ``--state-dir``).
    """

    def __init__(self, directory: str | Path) -> None:
        path = Path(directory)
        try:
            path.mkdir(parents=True, exist_ok=True)
            self.path = path / "state.sqlite3"
            self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
        except (OSError, sqlite3.Error) as exc:
            raise InputError("--state-dir", f"{path}: cannot open the state database: {exc}") from exc

    def close(self) -> None:
        self._db.close()

    def commit_inputs(self, inputs: Iterable[Input], wall_now: float, default_ttl_s: float | None) -> None:
        """Record the goal and threat inputs of one batch, in one transaction, before they are applied."""
        rows_t: list[tuple[str, bytes, float | None]] = []
        gone_t: list[tuple[str]] = []
        rows_g: list[tuple[str, bytes]] = []
        gone_g: list[tuple[str]] = []
        for inp in inputs:
            if isinstance(inp, ThreatPut):
                ttl = inp.update.ttl_s if inp.update.ttl_s is not None else default_ttl_s
                rows_t.append((inp.threat, encode(inp.update), None if ttl is None else wall_now + ttl))
            elif isinstance(inp, ThreatRemoved):
                gone_t.append((inp.threat,))
            elif isinstance(inp, GoalSet):
                rows_g.append((inp.unit, encode(inp.goal)))
            elif isinstance(inp, GoalCancelled):
                gone_g.append((inp.unit,))
        if not (rows_t or gone_t or rows_g or gone_g):
            return
        db = self._db
        db.execute("BEGIN")
        try:
            # a new goal or a cancel ends the old mission: its x0 and parameters no longer hold
            db.executemany("DELETE FROM missions WHERE unit = ?", [(u,) for u, _ in rows_g] + gone_g)
            db.executemany("INSERT OR REPLACE INTO threats VALUES (?, ?, ?)", rows_t)
            db.executemany("DELETE FROM threats WHERE id = ?", gone_t)
            db.executemany("INSERT OR REPLACE INTO goals VALUES (?, ?)", rows_g)
            db.executemany("DELETE FROM goals WHERE unit = ?", gone_g)
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise

    def commit_batch(
        self, batch: list[Input], wall_now: float, default_ttl_s: float | None, mission: str
    ) -> list[Input]:
        """``commit_inputs``, or, if the store fails, the batch with its goal and threat changes refused.

        Nothing is applied that was not committed: a refused change becomes an
        ``InputRejected`` naming the storage error, and the rest goes on.
        """
        try:
            self.commit_inputs(batch, wall_now, default_ttl_s)
            return batch
        except (OSError, sqlite3.Error) as exc:
            err = InputError("$", f"not stored: {exc}")
            kept: list[Input] = []
            for inp in batch:
                if isinstance(inp, GoalSet | GoalCancelled):
                    kept.append(InputRejected(keys.unit_goal(mission, inp.unit), err))
                elif isinstance(inp, ThreatPut | ThreatRemoved):
                    kept.append(InputRejected(keys.threat(mission, inp.threat), err))
                else:
                    kept.append(inp)
            return kept

    def record(self, missions: Iterable[MissionRecord], forgotten: Iterable[str]) -> None:
        """After an ``apply``: the missions it fixed, and the units it forgot."""
        self.record_missions(missions)
        self.forget(forgotten)

    def record_missions(self, missions: Iterable[MissionRecord]) -> None:
        """Record units' missions (``x0`` and resolved parameters) once they are fixed."""
        rows = [
            (m.unit, m.epoch, m.origin[0], m.origin[1], json.dumps(dataclasses.asdict(m.params)))
            for m in missions
        ]
        if rows:
            with self._db:
                self._db.execute("BEGIN")
                self._db.executemany("INSERT OR REPLACE INTO missions VALUES (?, ?, ?, ?, ?)", rows)

    def forget(self, units: Iterable[str]) -> None:
        """Units the world forgot: their goals and missions go too."""
        rows = [(u,) for u in units]
        if rows:
            with self._db:
                self._db.execute("BEGIN")
                self._db.executemany("DELETE FROM goals WHERE unit = ?", rows)
                self._db.executemany("DELETE FROM missions WHERE unit = ?", rows)

    def restore(self, wall_now: float) -> Restored:
        """The inputs that rebuild the world as it was: threats with the time left, goals, missions."""
        inputs: list[Input] = []
        expired = 0
        for tid, body, expires_at in self._db.execute("SELECT id, body, expires_at FROM threats ORDER BY id"):
            update = decode(ThreatUpdate, body)
            if expires_at is not None:
                left = expires_at - wall_now
                if left <= 0:
                    expired += 1
                    continue
                update = msgspec.structs.replace(update, ttl_s=left)
            inputs.append(ThreatPut(tid, update))
        n_threats = len(inputs)
        missions = {
            unit: (epoch, (ox, oy), Resolved(**json.loads(params)))
            for unit, epoch, ox, oy, params in self._db.execute("SELECT * FROM missions")
        }
        n_goals = n_missions = 0
        for unit, body in self._db.execute("SELECT unit, body FROM goals ORDER BY unit"):
            goal = decode(Goal, body)
            n_goals += 1
            if unit in missions:
                _epoch, origin, params = missions[unit]
                inputs.append(MissionRestored(unit, goal, origin, params))
                n_missions += 1
            else:
                inputs.append(GoalSet(unit, goal))
        if expired:
            with self._db:
                self._db.execute("BEGIN")
                self._db.execute(
                    "DELETE FROM threats WHERE expires_at IS NOT NULL AND expires_at <= ?", (wall_now,)
                )
        return Restored(inputs, n_threats, n_goals, n_missions, expired)
