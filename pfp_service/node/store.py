"""Durable state: what users gave the planner survives ``kill -9``, and survives its own damage.

One SQLite database in WAL mode per mission (``--state-dir``).  It holds the
threats and keep-out zones in force (with their absolute expiry, in Unix
time, so a restart honours the time that passed), the goals, and each unit's mission: ``x0``,
the goal and the resolved planner parameters, so a restored unit moves
exactly as it would have.

The node commits a batch's goal, threat and zone inputs *before* it applies them
(``commit_inputs``), so nothing a unit or a reporter saw acknowledged is
lost; missions are derived, and recorded after ``apply`` from the world's
``Outputs.missions``.  ``synchronous=NORMAL`` in WAL mode survives a killed
process (only a power cut can take the last transactions).

Damage.  At open the database is checked (``PRAGMA quick_check``).  A
damaged file is moved aside with its WAL, kept as
``state.sqlite3.corrupt-<UTC time>`` (``-wal``, ``-shm``), and the rows still
readable from it (``statefile.salvage``: the WAL's pages included, since SQLite reads
them first) are copied into a fresh database; the planner starts with those.
A row that reads but does not decode (``restore``) is moved to the
``set_aside`` table and named as ``table/key``; the rest loads.  Both are
said in one warning line and counted in ``Restored.corrupt``.  A full disk
or a read-only file is named as such (``statefile.describe``): at open it is an
``InputError`` (the CLI's one line and exit 2), later a refused input.

Who holds it.  A planner holds a shared ``flock`` on ``state.lock`` while it
runs; ``pfp state clear`` takes it exclusively, so it refuses a state that a
planner is using (``statefile.in_use``).

No zenoh here; times are passed in (the clock is read only to name a file
set aside when the caller gave no time).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import sqlite3
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pfp_service.errors import InputError
from pfp_service.node.log import get_logger
from pfp_service.node.statefile import (
    CORRUPT_CODES,
    DB_NAME,
    FILE_MODE,
    LOCK_NAME,
    describe,
    hold_shared,
    lenient_text,
    private_dir,
    private_files,
    salvage,
)
from pfp_service.node.staterows import OrderRow, Restored, read_state
from pfp_service.wire import encode
from pfp_service.wire.delivery import ORDER_KEYS_MAX
from pfp_service.world import kinds
from pfp_service.world.events import Input, MissionRecord
from pfp_service.world.kinds import WRITE_OF, Stored

__all__ = ["TABLES", "Restored", "Store"]

NAMED_MAX = 20  # rows named in the warning line at most; the count has them all

log = get_logger("store")


def _table_sql(st: Stored) -> str:
    """A write kind's table (``world.kinds.Stored``), as every state file since the first has it."""
    expires = ", expires_at REAL" if st.expiry != "never" else ""
    return f"CREATE TABLE IF NOT EXISTS {st.table} ({st.key_column} TEXT PRIMARY KEY, body BLOB NOT NULL{expires});"


_SCHEMA = (
    "\n".join(_table_sql(k.store) for k in kinds.STORED if k.store is not None)
    + """
CREATE TABLE IF NOT EXISTS missions (
    unit TEXT PRIMARY KEY, epoch INTEGER NOT NULL, origin_x REAL NOT NULL, origin_y REAL NOT NULL, params TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS set_aside (tbl TEXT NOT NULL, key TEXT, body BLOB, reason TEXT NOT NULL, at REAL);
CREATE TABLE IF NOT EXISTS write_order (
    key TEXT PRIMARY KEY, newest_t REAL NOT NULL, newest_w TEXT NOT NULL, applied_t REAL NOT NULL, applied_w TEXT NOT NULL
);
"""
)
_PAGE = re.compile(r"\bPage (\d+)")
# table -> (key column, column count): what a salvage copies and how a lost row is named
TABLES: dict[str, tuple[str, int]] = {
    **{
        k.store.table: (k.store.key_column, len(k.store.columns)) for k in kinds.STORED if k.store is not None
    },
    "missions": ("unit", 5),
    "write_order": ("key", 5),
}


@dataclasses.dataclass
class _Damage:
    """A damaged file found at open: where it went, why, and what could not be read from it."""

    moved_to: str
    reason: str
    pages: int
    lost: list[str]
    salvaged: dict[str, int]


def _corrupt(exc: BaseException) -> bool:
    # a damaged file may also make SQLite's own message undecodable: Python raises that instead
    if isinstance(exc, UnicodeDecodeError):
        return True
    code = getattr(exc, "sqlite_errorcode", None)
    return isinstance(code, int) and code & 0xFF in CORRUPT_CODES


class Store:
    """The planner's durable state in ``directory/state.sqlite3``.

    Args:
        directory: the mission's state directory (made if missing).
        wall_now: Unix time, to name a damaged file set aside (read from the clock if not given).

    Raises:
        InputError: the directory cannot be made, or the database opened or created
            (path ``--state-dir``; the reason names the file and says why: disk full, read-only ...).
    """

    def __init__(self, directory: str | Path, wall_now: float | None = None) -> None:
        path = Path(directory)
        self.path = path / DB_NAME
        self.damage: _Damage | None = None
        self._lock: int | None = None
        self._complained: set[str] = set()
        self._order_commits = 0
        try:
            private_dir(path)  # 0700, parents made too; the files 0600 (SQLite gives its WAL the db's mode)
            self._lock = hold_shared(path / LOCK_NAME)
            private_files(path, (LOCK_NAME, DB_NAME, f"{DB_NAME}-wal", f"{DB_NAME}-shm"))
        except OSError as exc:
            raise InputError(
                "--state-dir", f"{path}: cannot use the state directory: {describe(exc)}"
            ) from exc
        try:
            try:
                self._db = self._open_checked()
            except (sqlite3.DatabaseError, UnicodeDecodeError) as exc:
                if not (_corrupt(exc) or isinstance(exc, _Damaged)):
                    raise
                self._db = self._recover(str(exc), wall_now, getattr(exc, "pages", 0))
        except (OSError, sqlite3.Error, UnicodeDecodeError) as exc:
            self._unlock()
            raise InputError(
                "--state-dir", f"{self.path}: cannot open the state database: {describe(exc)}"
            ) from exc

    # -- opening, checking, recovering ---------------------------------------------------
    def _connect(self) -> sqlite3.Connection:
        if not self.path.exists():  # made 0600 here: SQLite would take the umask's mode
            os.close(os.open(self.path, os.O_RDWR | os.O_CREAT, FILE_MODE))
        db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        db.text_factory = lenient_text  # a damaged key reads as text, and is then refused as a key
        return db

    def _open_checked(self) -> sqlite3.Connection:
        db = self._connect()
        try:
            found = [row[0] for row in db.execute("PRAGMA quick_check")]
            if found != ["ok"]:
                raise _Damaged("; ".join(map(str, found[:3])), _pages(found))
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=NORMAL")
            db.executescript(_SCHEMA)
        except BaseException:
            db.close()
            raise
        return db

    def _recover(self, reason: str, wall_now: float | None, pages: int = 0) -> sqlite3.Connection:
        """Move the damaged file (and its WAL) aside, keep it, and start afresh with what it still holds."""
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(time.time() if wall_now is None else wall_now))
        aside = self.path.with_name(f"{DB_NAME}.corrupt-{stamp}")
        n = 1
        while aside.exists():
            aside = self.path.with_name(f"{DB_NAME}.corrupt-{stamp}-{n}")
            n += 1
        for suffix in ("", "-wal", "-shm"):  # SQLite finds a WAL by its name: the copy keeps its own
            src = Path(f"{self.path}{suffix}")
            if src.exists():
                os.replace(src, f"{aside}{suffix}")
        rows, lost = salvage(aside, TABLES)
        db = self._connect()
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=NORMAL")
            db.executescript(_SCHEMA)
            db.execute("BEGIN")
            salvaged = {}
            for table, got in rows.items():
                width = TABLES[table][1]
                marks = ", ".join("?" * width)
                kept = 0
                for row in got:
                    try:
                        db.execute(f"INSERT OR REPLACE INTO {table} VALUES ({marks})", row[:width])
                        kept += 1
                    except sqlite3.IntegrityError:  # a NULL where none may be: unreadable
                        lost.append(f"{table}/{row[0]}")
                salvaged[table] = kept
            db.execute("COMMIT")
        except BaseException:
            db.close()
            raise
        self.damage = _Damage(str(aside), reason, pages, lost, salvaged)
        return db

    def close(self) -> None:
        self._db.close()
        self._unlock()

    def _unlock(self) -> None:
        if self._lock is not None:
            os.close(self._lock)  # the flock goes with the descriptor
            self._lock = None

    # -- writing -------------------------------------------------------------------------
    def commit_inputs(
        self,
        inputs: Iterable[Input],
        wall_now: float,
        default_ttl_s: float | None,
        order: Iterable[OrderRow] = (),
    ) -> None:
        """Record the goal, threat and zone inputs of one batch, in one transaction, before they are applied.

        ``order``: the write order of the keys the batch wrote (``WriteOrder.batch_rows``), kept in
        the same transaction, so a restarted planner knows which write each key saw last.
        """
        order_rows = list(order)
        rows: dict[Stored, list[tuple[Any, ...]]] = {}  # per write kind's table: the rows put
        gone: dict[Stored, list[tuple[str]]] = {}  # ... and the ids removed
        for inp in inputs:
            got = WRITE_OF.get(type(inp))
            if got is None or got[0].store is None:
                continue
            st, ident = got[0].store, kinds.ident(inp)
            if not got[1]:
                gone.setdefault(st, []).append((ident,))
                continue
            msg = kinds.message(inp)
            row: tuple[Any, ...] = (ident, encode(msg))
            if st.expiry != "never":  # kept as absolute Unix time: a restart honours the time that passed
                ttl = msg.ttl_s
                if ttl is None and st.expiry == "ttl_or_default":
                    ttl = default_ttl_s
                row += (None if ttl is None else wall_now + ttl,)
            rows.setdefault(st, []).append(row)
        if not (rows or gone or order_rows):
            return
        with self._transaction() as db:
            db.executemany("INSERT OR REPLACE INTO write_order VALUES (?, ?, ?, ?, ?)", order_rows)
            self._order_commits += bool(order_rows)
            if order_rows and self._order_commits % 1024 == 0:  # as many keys as the planner remembers
                db.execute(
                    "DELETE FROM write_order WHERE key NOT IN "
                    "(SELECT key FROM write_order ORDER BY newest_t DESC LIMIT ?)",
                    (ORDER_KEYS_MAX,),
                )
            for st in {**rows, **gone}:
                put, removed = rows.get(st, []), gone.get(st, [])
                if (
                    st.per_unit
                ):  # a new goal or a cancel ends the old mission: its x0 and parameters no longer hold
                    db.executemany("DELETE FROM missions WHERE unit = ?", [r[:1] for r in put] + removed)
                marks = ", ".join("?" * len(st.columns))
                db.executemany(f"INSERT OR REPLACE INTO {st.table} VALUES ({marks})", put)
                db.executemany(f"DELETE FROM {st.table} WHERE {st.key_column} = ?", removed)

    @contextlib.contextmanager
    def _transaction(self) -> Any:
        """BEGIN ... COMMIT; on failure the original error, not the ROLLBACK's.

        SQLite rolls a transaction back by itself on a full disk or an I/O
        error; a ROLLBACK then fails with "no transaction is active" and, if
        raised, would hide the cause.
        """
        db = self._db
        db.execute("BEGIN")
        try:
            yield db
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                with contextlib.suppress(sqlite3.Error):
                    db.execute("ROLLBACK")
            raise

    def commit_batch(
        self, batch: list[Input], wall_now: float, default_ttl_s: float | None, mission: str
    ) -> list[Input]:
        """``commit_writes`` without a write order: the batch to apply."""
        return self.commit_writes(batch, wall_now, default_ttl_s, mission)[0]

    def commit_writes(
        self,
        batch: list[Input],
        wall_now: float,
        default_ttl_s: float | None,
        mission: str,
        order: Iterable[OrderRow] = (),
    ) -> tuple[list[Input], str | None]:
        """``commit_inputs``; the batch to apply, and why the store refused it (``None``: committed).

        Nothing is applied that was not committed: if the store fails, each goal,
        threat and zone change becomes an ``InputRejected`` naming the storage
        error (disk full, read-only ...) and the state file, and the rest goes on.
        """
        try:
            self.commit_inputs(batch, wall_now, default_ttl_s, order)
            return batch, None
        except (OSError, sqlite3.Error) as exc:
            err = InputError("$", f"not stored: {describe(exc)}: {self.path}")
            self._complain("commit", err.reason)
            return [kinds.rejected(inp, mission, err) for inp in batch], err.reason

    def _complain(self, what: str, reason: str) -> None:
        # one warning line per distinct failure, not one per batch while the disk stays full
        if reason not in self._complained and len(self._complained) < 64:
            self._complained.add(reason)
            log.warning(
                f"state not stored ({what})", extra={"fields": {"state": str(self.path), "reason": reason}}
            )

    def record(self, missions: Iterable[MissionRecord], forgotten: Iterable[str]) -> None:
        """After an ``apply``: the missions it fixed, and the units it forgot.

        A storage failure here is logged, not raised: the goals are stored, and
        a unit whose mission was not recorded is restored from its goal.
        """
        try:
            self.record_missions(missions)
            self.forget(forgotten)
        except (OSError, sqlite3.Error) as exc:
            self._complain("missions", f"{describe(exc)}: {self.path}")

    def record_missions(self, missions: Iterable[MissionRecord]) -> None:
        """Record units' missions (``x0`` and resolved parameters) once they are fixed."""
        rows = [
            (m.unit, m.epoch, m.origin[0], m.origin[1], json.dumps(dataclasses.asdict(m.params)))
            for m in missions
        ]
        if rows:
            with self._transaction() as db:
                db.executemany("INSERT OR REPLACE INTO missions VALUES (?, ?, ?, ?, ?)", rows)

    def forget(self, units: Iterable[str]) -> None:
        """Units the world forgot: their goals and missions go too."""
        rows = [(u,) for u in units]
        if rows:
            with self._transaction() as db:
                db.executemany("DELETE FROM goals WHERE unit = ?", rows)
                db.executemany("DELETE FROM missions WHERE unit = ?", rows)

    # -- reading -------------------------------------------------------------------------
    def restore(self, wall_now: float) -> Restored:
        """The inputs that rebuild the world as it was: zones and threats with the time left, goals, missions.

        A row that does not decode is moved to ``set_aside`` and named; the
        rest loads.  A read that finds the file damaged (past the check at
        open) sets the file aside as ``__init__`` would, and reads again.

        Raises:
            InputError: the database cannot be read at all (an I/O error), naming the file.
        """
        try:
            try:
                found = read_state(self._db, wall_now, self._transaction)
            except (sqlite3.DatabaseError, UnicodeDecodeError) as exc:
                if not _corrupt(exc):
                    raise
                self._db.close()
                self._db = self._recover(str(exc), wall_now)
                found = read_state(self._db, wall_now, self._transaction)
        except (OSError, sqlite3.Error, UnicodeDecodeError) as exc:
            raise InputError(
                "--state-dir", f"{self.path}: cannot read the state database: {describe(exc)}"
            ) from exc
        damage = self.damage
        lost = damage.lost if damage is not None else []
        skipped = tuple(lost) + found.skipped
        corrupt = len(skipped) + (max(1, damage.pages) if damage is not None else 0)
        restored = dataclasses.replace(
            found,
            corrupt=corrupt,
            set_aside=damage.moved_to if damage is not None else "",
            skipped=skipped,
        )
        if corrupt:
            self._say(restored)
        return restored

    def _say(self, r: Restored) -> None:
        """The one warning line: what was set aside, where it went, and what was kept."""
        names = ", ".join(r.skipped[:NAMED_MAX]) + (
            f" and {len(r.skipped) - NAMED_MAX} more" if len(r.skipped) > NAMED_MAX else ""
        )
        fields: dict[str, Any] = {"state": str(self.path), "corrupt": r.corrupt}
        if self.damage is not None:
            fields |= {
                "moved_to": self.damage.moved_to,
                "reason": self.damage.reason,
                "salvaged": " ".join(f"{t}:{n}" for t, n in self.damage.salvaged.items()),
            }
        if names:
            fields["skipped"] = names
        what = (
            "damaged state file set aside" if self.damage is not None else "unreadable state rows set aside"
        )
        log.warning(f"{what}; started with the rest", extra={"fields": fields})


class _Damaged(sqlite3.DatabaseError):
    """``quick_check`` found damage (it names the pages)."""

    def __init__(self, reason: str, pages: int) -> None:
        super().__init__(reason)
        self.pages = pages


def _pages(found: list[Any]) -> int:
    return len({m.group(1) for line in found for m in _PAGE.finditer(str(line))})
