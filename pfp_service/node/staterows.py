"""The rows of the durable state read back as inputs: what a restarted planner applies, and what it sets aside.

``read_state`` decodes each table of ``state.sqlite3`` (``store.Store`` owns the file): zones and
threats with the time each has left, goals with their missions, and the write order kept with
the writes (``wire.delivery.WriteOrder.load``).  A row that does not decode is moved to the
``set_aside`` table and named; the rest loads.  No zenoh, no clock: the time is passed in.
"""

from __future__ import annotations

import dataclasses
import json
import sqlite3
from collections.abc import Callable
from typing import Any, TypeVar

import msgspec

from pfp_service.core.params import Resolved
from pfp_service.errors import InputError
from pfp_service.wire import Goal, ThreatUpdate, decode, keys
from pfp_service.wire.messages import TeamUpdate, ZoneUpdate
from pfp_service.world.events import GoalSet, Input, MissionRestored, TeamPut, ThreatPut, ZonePut

__all__ = ["OrderRow", "Restored", "read_state"]

U = TypeVar("U", ThreatUpdate, ZoneUpdate, TeamUpdate)  # a write kept by id (a team never expires)
OrderRow = tuple[str, float, str, float, str]  # wire.delivery.WriteOrder.batch_rows
_BAD_ROW = (InputError, ValueError, TypeError, KeyError, msgspec.MsgspecError)


@dataclasses.dataclass(frozen=True)
class Restored:
    """What a restart found: inputs to apply, and the counts for the ``restored`` event.

    ``corrupt`` counts the rows skipped as unreadable (named in ``skipped`` as
    ``table/key``), plus the damaged pages of a file set aside (at least one);
    ``set_aside`` is where that file was moved, or ``""``.
    """

    inputs: list[Input]
    threats: int
    goals: int
    missions: int
    expired: int
    corrupt: int = 0
    set_aside: str = ""
    skipped: tuple[str, ...] = ()
    zones: int = 0
    order: tuple[OrderRow, ...] = ()
    teams: int = 0  # the write order kept (WriteOrder.load)


def read_state(db: sqlite3.Connection, wall_now: float, transaction: Callable[[], Any]) -> Restored:
    """The inputs that rebuild the world from ``db``; a row that does not decode is moved to ``set_aside``
    in a ``transaction()`` and named in ``Restored.skipped``."""
    inputs: list[Input] = []
    bad: list[tuple[str, int, str, Any, str]] = []  # table, rowid, key, what was stored, why
    expired = 0

    def timed(table: str, kind: type[U], put: Callable[[str, U], Input]) -> int:
        """The rows of a table of writes that expire (zones, threats), with the time each has left."""
        nonlocal expired
        n = 0
        for rowid, key, body, expires_at in db.execute(f"SELECT rowid, * FROM {table} ORDER BY id"):
            try:
                chunk = keys.check_chunk(key)
                update = decode(kind, body)
                if expires_at is not None and not isinstance(update, TeamUpdate):
                    left = float(expires_at) - wall_now
                    if left <= 0:
                        expired += 1
                        continue
                    update = msgspec.structs.replace(update, ttl_s=left)
            except _BAD_ROW as exc:
                bad.append((table, rowid, str(key), body, _why(exc)))
                continue
            inputs.append(put(chunk, update))
            n += 1
        return n

    n_teams = timed("teams", TeamUpdate, TeamPut)
    n_zones = timed("zones", ZoneUpdate, ZonePut)
    n_threats = timed("threats", ThreatUpdate, ThreatPut)
    missions: dict[str, tuple[tuple[float, float], Resolved]] = {}
    for rowid, unit, _epoch, ox, oy, params in db.execute("SELECT rowid, * FROM missions"):
        try:
            missions[keys.check_chunk(unit)] = ((float(ox), float(oy)), Resolved(**json.loads(params)))
        except _BAD_ROW as exc:
            bad.append(("missions", rowid, str(unit), params, _why(exc)))
    n_goals = n_missions = 0
    for rowid, unit, body in db.execute("SELECT rowid, * FROM goals ORDER BY unit"):
        try:
            uid = keys.check_chunk(unit)
            goal = decode(Goal, body)
        except _BAD_ROW as exc:
            bad.append(("goals", rowid, str(unit), body, _why(exc)))
            continue
        n_goals += 1
        if uid in missions:
            origin, params = missions[uid]
            inputs.append(MissionRestored(uid, goal, origin, params))
            n_missions += 1
        else:
            inputs.append(GoalSet(uid, goal))
    order: list[OrderRow] = []  # the write order kept: read as it is (a bad time is set aside)
    for rowid, key, nt, nw, at, aw in db.execute("SELECT rowid, * FROM write_order"):
        try:
            order.append((str(key), float(nt), str(nw), float(at), str(aw)))
        except _BAD_ROW as exc:
            bad.append(("write_order", rowid, str(key), None, _why(exc)))
    if expired or bad:
        with transaction() as tx:
            for table in ("threats", "zones"):
                tx.execute(
                    f"DELETE FROM {table} WHERE expires_at IS NOT NULL AND expires_at <= ?", (wall_now,)
                )
            for (
                table,
                rowid,
                key,
                body,
                why,
            ) in bad:  # kept, out of the way: a later start does not trip on it
                tx.execute("INSERT INTO set_aside VALUES (?, ?, ?, ?, ?)", (table, key, body, why, wall_now))
                tx.execute(f"DELETE FROM {table} WHERE rowid = ?", (rowid,))
    skipped = tuple(f"{table}/{key}" for table, _r, key, _b, _w in bad)
    return Restored(
        inputs,
        n_threats,
        n_goals,
        n_missions,
        expired,
        skipped=skipped,
        zones=n_zones,
        order=tuple(order),
        teams=n_teams,
    )


def _why(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__
