"""The state database as files: salvage from a damaged one, who holds it, what a mission's directory holds.

``Store`` opens, checks and writes the database; this module is what it and
``pfp state`` need of the files around it: ``salvage`` reads what it can
from a file set aside, ``hold_shared`` and ``in_use`` are the planner's lock
(a shared ``flock`` on ``state.lock``, which ``pfp state clear`` takes
exclusively), ``state_files`` reads a directory without changing it, and
``describe`` puts a storage error in an operator's words.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
import sqlite3
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

try:  # POSIX; elsewhere nothing is locked and ``in_use`` is always false
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "CORRUPT_CODES",
    "DB_NAME",
    "DIR_MODE",
    "FILE_MODE",
    "LOCK_NAME",
    "StateFiles",
    "clear",
    "describe",
    "hold_shared",
    "in_use",
    "lenient_text",
    "private_dir",
    "private_files",
    "salvage",
    "state_files",
]

DB_NAME = "state.sqlite3"
LOCK_NAME = "state.lock"
# Other durable state kept in a mission's directory by our clients, removed with it: the TAK bridge's
# tombstones (``pfp_clients.tak.tombfile.FILE_NAME``; a test checks the two names agree), and their damaged copies.
COMPANION_NAMES = ("tak-tombstones.json",)
CORRUPT_CODES = (11, 26)  # SQLITE_CORRUPT, SQLITE_NOTADB
SCAN_QUERIES = 10_000  # a salvage scan of one table gives up after this many queries
_TABLE_NAME = re.compile(
    r"^[a-z_]{1,64}$"
)  # a table ``state_files`` counts (our names; a hostile file's others are not)


def describe(exc: BaseException) -> str:
    """A storage error in words a field operator acts on: the disk is full, the file is read-only ..."""
    code = getattr(exc, "sqlite_errorcode", None)
    errno = getattr(exc, "errno", None)
    primary = code & 0xFF if isinstance(code, int) else None
    if primary == 13 or errno == 28:  # SQLITE_FULL, ENOSPC
        return f"the disk is full ({exc})"
    if primary == 8:  # SQLITE_READONLY
        return f"the state database is read-only ({exc})"
    if errno == 30:  # EROFS
        return f"the file system is read-only ({exc})"
    if primary == 3 or errno in (1, 13):  # SQLITE_PERM, EPERM, EACCES
        return f"permission denied ({exc})"
    if primary in CORRUPT_CODES:
        return f"the state database is damaged ({exc})"
    if primary in (5, 6):  # SQLITE_BUSY, SQLITE_LOCKED
        return f"the state database is locked by another process ({exc})"
    if primary == 10:  # SQLITE_IOERR
        return f"I/O error ({exc})"
    return str(exc)


def lenient_text(raw: bytes) -> str:
    """SQLite text as ``str`` even when a damaged file holds bytes that are not UTF-8 (they read as U+FFFD)."""
    return raw.decode("utf-8", "replace")


# -- salvage -------------------------------------------------------------------------------
def salvage(
    path: str | Path, tables: Mapping[str, tuple[str, int]]
) -> tuple[dict[str, list[tuple[Any, ...]]], list[str]]:
    """The rows still readable from a damaged database, per table, and ``table/key`` of rows known lost.

    ``tables``: table -> (key column, column count), what is copied and how a lost row is named
    (``store.TABLES``, from the write kinds' table, ``world.kinds``).

    Each table is scanned in rowid order; where a page cannot be read the scan
    starts again past it (at rowid steps doubling until one reads).  A key
    found in the table's primary-key index whose row was not read is known
    lost.  Opened read-only (``mode=ro``): the file set aside stays as found.
    """
    rows: dict[str, list[tuple[Any, ...]]] = {t: [] for t in tables}
    lost: list[str] = []
    try:
        db = sqlite3.connect(f"file:{Path(path).as_posix()}?mode=ro", uri=True)
        db.text_factory = lenient_text
    except sqlite3.Error:
        return rows, lost
    try:
        for table, (key, _width) in tables.items():
            if not _has_table(db, table):  # an older file, made before the table was
                continue
            got = _scan(db, table)
            rows[table] = list(got.values())
            have = {str(r[0]) for r in got.values()}
            lost += [f"{table}/{k}" for k in _index_keys(db, table, key) if k not in have]
    finally:
        db.close()
    return rows, lost


def _has_table(db: sqlite3.Connection, table: str) -> bool:
    try:
        return (
            db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (table,)).fetchone()
            is not None
        )
    except (sqlite3.Error, UnicodeDecodeError):  # the schema page itself is damaged: try the table anyway
        return True


def _scan(db: sqlite3.Connection, table: str) -> dict[int, tuple[Any, ...]]:
    # Every query either reads a new row (rowids only grow) or jumps further: it ends.  A damaged
    # tree may hand rows back out of order; that is treated as a page that cannot be read.
    got: dict[int, tuple[Any, ...]] = {}
    after, jump = 0, 0
    for _query in range(SCAN_QUERIES):
        if after >= 2**62:
            break
        try:
            for row in db.execute(f"SELECT rowid, * FROM {table} WHERE rowid > ? ORDER BY rowid", (after,)):
                if not isinstance(row[0], int) or row[0] <= after:
                    raise sqlite3.DatabaseError("rows out of order")
                got[row[0]] = tuple(row[1:])
                after, jump = row[0], 0
            return got
        except (sqlite3.Error, UnicodeDecodeError):  # this page is gone: try past it
            jump += 1
            after += 1 << jump
    return got


def _index_keys(db: sqlite3.Connection, table: str, key: str) -> list[str]:
    out: list[str] = []
    with contextlib.suppress(sqlite3.Error, UnicodeDecodeError):
        for (k,) in db.execute(
            f"SELECT {key} FROM {table} INDEXED BY sqlite_autoindex_{table}_1 ORDER BY {key}"
        ):
            out.append(str(k))
    return out


# -- who holds it, what is there (``pfp state``) ----------------------------------------
# The state is the mission (goals, threats, positions): only its owner reads it, whatever the umask.
DIR_MODE = 0o700
FILE_MODE = 0o600


def private_dir(path: Path) -> None:
    """Make ``path`` and each missing parent with mode 0700, and set 0700 on ``path`` if it exists.

    Raises:
        OSError: it cannot be made.
    """
    missing = [p for p in (path, *path.parents) if not p.exists()]
    for p in reversed(missing):
        with contextlib.suppress(FileExistsError):  # made meanwhile by another process
            p.mkdir(mode=DIR_MODE)
    if (path.stat().st_mode & 0o777) != DIR_MODE:
        with contextlib.suppress(PermissionError):  # not ours to change: used as it is
            os.chmod(path, DIR_MODE)


def private_files(directory: Path, names: Iterable[str]) -> None:
    """Mode 0600 on each of ``names`` in ``directory`` that exists (a file an older planner made 0644)."""
    for name in names:
        with contextlib.suppress(FileNotFoundError, PermissionError):
            f = directory / name
            if (f.stat().st_mode & 0o777) != FILE_MODE:
                os.chmod(f, FILE_MODE)


def hold_shared(lock_path: Path) -> int | None:
    """A shared flock on ``state.lock``, held until closed; retried if ``clear`` removed the file meanwhile."""
    if fcntl is None:  # pragma: no cover
        return None
    for _ in range(100):
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, FILE_MODE)
        try:
            fcntl.flock(fd, fcntl.LOCK_SH)
            if os.fstat(fd).st_ino == os.stat(lock_path).st_ino:
                return fd
        except FileNotFoundError:
            pass
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)
    raise OSError(f"{lock_path}: could not be locked")


def in_use(directory: str | Path) -> bool:
    """A planner holds this state directory (its shared lock on ``state.lock``)."""
    lock_path = Path(directory) / LOCK_NAME
    if fcntl is None or not lock_path.exists():
        return False
    fd = os.open(lock_path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


@dataclasses.dataclass(frozen=True)
class StateFiles:
    """A mission's state directory as ``pfp state list`` shows it.

    ``counts`` holds the rows per table (``threats``, ``zones``, ``goals``, ``missions``,
    ``set_aside``), empty when the database cannot be read; ``error`` says why.
    """

    directory: Path
    files: tuple[Path, ...]
    bytes: int
    counts: dict[str, int]
    set_aside_files: tuple[Path, ...]
    error: str


def state_files(directory: str | Path) -> StateFiles:
    """What a mission's state directory holds, read without changing it (``mode=ro``)."""
    d = Path(directory)
    files = tuple(sorted(p for p in d.glob(f"{DB_NAME}*") if p.is_file())) if d.is_dir() else ()
    aside = tuple(p for p in files if ".corrupt-" in p.name and not p.name.endswith(("-wal", "-shm")))
    counts: dict[str, int] = {}
    error = ""
    db_path = d / DB_NAME
    if db_path.exists():
        try:
            db = sqlite3.connect(f"file:{db_path.as_posix()}?mode=ro", uri=True)
            db.text_factory = lenient_text
            try:
                # every table the file has: this light module knows no kind's table (world.kinds)
                named = db.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY rowid")
                for table in [str(r[0]) for r in named if _TABLE_NAME.match(str(r[0]))]:
                    with contextlib.suppress(sqlite3.OperationalError):
                        counts[table] = int(db.execute(f"SELECT count(*) FROM {table}").fetchone()[0])
            finally:
                db.close()
        except (sqlite3.Error, UnicodeDecodeError) as exc:
            error = describe(exc)
    return StateFiles(d, files, sum(p.stat().st_size for p in files), counts, aside, error)


def clear(directory: str | Path) -> list[tuple[Path, int]]:
    """Remove a mission's state files (the database, its WAL, files set aside, the TAK bridge's tombstones, the
    lock); the directory if empty.

    Returns:
        Each file removed, with its size; empty when there was nothing.

    Raises:
        BlockingIOError: a planner holds the state (``in_use``); nothing was removed.
        OSError: a file could not be removed.
    """
    d = Path(directory)
    names = (DB_NAME, *COMPANION_NAMES)
    files = [p for n in names for p in d.glob(f"{n}*") if p.is_file()] if d.is_dir() else []
    if not files:
        return []
    lock_path = d / LOCK_NAME
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, FILE_MODE)
    try:
        if fcntl is not None:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # BlockingIOError while a planner holds it
        removed = []
        for p in sorted(files):
            size = p.stat().st_size
            p.unlink()
            removed.append((p, size))
        lock_path.unlink()  # while held: a planner waiting on it sees it gone and takes a new one
    finally:
        os.close(fd)
    with contextlib.suppress(OSError):
        d.rmdir()
    return removed
