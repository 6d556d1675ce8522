"""The rows of the durable state read back as inputs: what a restarted planner applies, and what it sets aside.

``read_state`` decodes each table of ``state.sqlite3`` (``store.Store`` owns the file): each write
kind's (``world.kinds``: threats and zones with the time each has left, goals with their
missions), and the write order kept with
the writes (``wire.delivery.WriteOrder.load``).  A row that does not decode is moved to the
``set_aside`` table and named; the rest loads.  No zenoh, no clock: the time is passed in.
"""

from __future__ import annotations

import dataclasses
import json
import sqlite3
from collections.abc import Callable
from typing import Any

import msgspec

from pfp_service.core.params import Resolved
from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.world.events import Input, MissionRestored
from pfp_service.world.kinds import STORED, Kind, Stored

__all__ = ["OrderRow", "Restored", "read_state"]

OrderRow = tuple[str, float, str, float, str]  # wire.delivery.WriteOrder.batch_rows
_BAD_ROW = (InputError, ValueError, TypeError, KeyError, msgspec.MsgspecError)


@dataclasses.dataclass(frozen=True)
class Restored:
    """What a restart found: inputs to apply, and the counts for the ``restored`` event.

    ``kept``: the rows restored per stored write kind, by its name (``world.kinds.STORED``:
    ``{"threat": 20, "goal": 50, ...}``, every stored kind named); ``corrupt`` counts the rows skipped as unreadable (named in ``skipped`` as
    ``table/key``), plus the damaged pages of a file set aside (at least one);
    ``set_aside`` is where that file was moved, or ``""``.
    """

    inputs: list[Input]
    kept: dict[str, int]
    missions: int
    expired: int
    corrupt: int = 0
    set_aside: str = ""
    skipped: tuple[str, ...] = ()
    order: tuple[OrderRow, ...] = ()  # the write order kept (WriteOrder.load)


def read_state(db: sqlite3.Connection, wall_now: float, transaction: Callable[[], Any]) -> Restored:
    """The inputs that rebuild the world from ``db``; a row that does not decode is moved to ``set_aside``
    in a ``transaction()`` and named in ``Restored.skipped``.

    Each write kind's table (``world.kinds.Stored``) is read as its puts, the time left on one
    that expires; a unit's (goals) after the rest, since its mission is planned among them, and
    as its mission where one was recorded.
    """
    inputs: list[Input] = []
    bad: list[tuple[str, int, str, Any, str]] = []  # table, rowid, key, what was stored, why
    expired = 0
    missions: dict[str, tuple[tuple[float, float], Resolved]] = {}
    kept: dict[str, int] = {}  # rows restored, per kind
    n_missions, n_missions_read = 0, False

    def puts(kind: Kind, st: Stored) -> int:
        """The rows of one write kind's table, as its puts."""
        nonlocal expired, n_missions
        n = 0
        for rowid, key, body, *expires in db.execute(
            f"SELECT rowid, * FROM {st.table} ORDER BY {st.key_column}"
        ):
            try:
                chunk = keys.check_chunk(key)
                assert kind.decode is not None
                msg = kind.decode(body, None, None)
                if expires and expires[0] is not None:
                    left = float(expires[0]) - wall_now
                    if left <= 0:
                        expired += 1
                        continue
                    msg = msgspec.structs.replace(msg, ttl_s=left)
            except _BAD_ROW as exc:
                bad.append((st.table, rowid, str(key), body, _why(exc)))
                continue
            n += 1
            if st.per_unit and chunk in missions:
                origin, params = missions[chunk]
                inputs.append(MissionRestored(chunk, msg, origin, params))
                n_missions += 1
            else:
                inputs.append(kind.put(chunk, msg))
        return n

    stored = [(k, k.store) for k in STORED if k.store is not None]
    for kind, st in stored:  # a unit's after the rest (its mission is planned among them)
        if st.per_unit and not n_missions_read:
            n_missions_read = True
            for rowid, unit, _epoch, ox, oy, params in db.execute("SELECT rowid, * FROM missions"):
                try:
                    missions[keys.check_chunk(unit)] = (
                        (float(ox), float(oy)),
                        Resolved(**json.loads(params)),
                    )
                except _BAD_ROW as exc:
                    bad.append(("missions", rowid, str(unit), params, _why(exc)))
        kept[kind.name] = puts(kind, st)
    order: list[OrderRow] = []  # the write order kept: read as it is (a bad time is set aside)
    for rowid, key, nt, nw, at, aw in db.execute("SELECT rowid, * FROM write_order"):
        try:
            order.append((str(key), float(nt), str(nw), float(at), str(aw)))
        except _BAD_ROW as exc:
            bad.append(("write_order", rowid, str(key), None, _why(exc)))
    if expired or bad:
        with transaction() as tx:
            for _kind, st in stored:
                if st.expiry != "never":
                    tx.execute(
                        f"DELETE FROM {st.table} WHERE expires_at IS NOT NULL AND expires_at <= ?",
                        (wall_now,),
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
    return Restored(inputs, kept, n_missions, expired, skipped=skipped, order=tuple(order))


def _why(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__
