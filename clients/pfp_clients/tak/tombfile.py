"""The bridge's tombstones on disk, so a restarted ``pfp tak`` does not revive a deleted marker.

A TAK server keeps every marker until its stale time and replays it on each
connection, deletes or not; the tombstones (``state.Tombstone``) are what
refuses those replays.  In memory they survive a link's reconnect; in this
file they survive the process.  One JSON object, ``{uid: [after, until, source]}``
(Unix seconds; ``source`` may be missing in an older file), written whole to a
temporary file and renamed over the old one, so a crash leaves the old file or
the new one, never half of either.  It stays within the size ``load`` reads by
construction: at most ``MAX_TOMBSTONES`` entries, each uid at most
``cot.MAX_UID_CHARS`` characters and each source at most ``MAX_SOURCE_CHARS``
(``_MAX_BYTES`` is checked against that at import).

A file that cannot be read (damaged, not ours) is moved aside as
``<name>.corrupt-<unix s>`` and the bridge starts without it; every failure
is a value (``Loaded.note``), never an exception, and the bridge carries on.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import msgspec

from pfp_clients.tak.cot import MAX_UID_CHARS
from pfp_clients.tak.state import BridgeState
from pfp_clients.tak.tombs import MAX_TOMBSTONES, Tombstone
from pfp_service.node.statefile import FILE_MODE, private_dir

__all__ = ["FILE_NAME", "Keeper", "Loaded", "load", "save"]

FILE_NAME = "tak-tombstones.json"
_MAX_BYTES = 16 * 1024 * 1024  # the most a file of ours can be (below); more is not our file
MAX_SOURCE_CHARS = 64  # a link's name as the bridge gives it; longer is cut in the file
# every character JSON-escaped (6 bytes), two floats of up to 24 characters, and the punctuation
_ENTRY_MAX_BYTES = 6 * (MAX_UID_CHARS + MAX_SOURCE_CHARS) + 2 * 24 + 16
assert MAX_TOMBSTONES * _ENTRY_MAX_BYTES + 2 <= _MAX_BYTES, "a full tombstone file would be set aside"


@dataclass(frozen=True, slots=True)
class Loaded:
    """What ``load`` found: the tombstones, and one line to log when something was wrong."""

    tombstones: dict[str, Tombstone] = field(default_factory=dict)
    note: str | None = None


def _decode(data: bytes) -> dict[str, Tombstone]:
    raw = msgspec.json.decode(data, type=dict[str, list[float | str]])
    out = {}
    for uid, entry in raw.items():
        if len(entry) not in (2, 3) or not all(isinstance(v, float | int) for v in entry[:2]):
            raise ValueError(f"{uid!r}: not [after, until] or [after, until, source]")
        after, until, source = float(entry[0]), float(entry[1]), entry[2] if len(entry) == 3 else ""
        if not (uid and math.isfinite(after) and math.isfinite(until) and isinstance(source, str)):
            raise ValueError(f"{uid!r}: not a uid with two finite times")
        out[uid] = Tombstone(after, until, source)
    return out


def load(path: Path, now: float) -> Loaded:
    """The tombstones kept in ``path`` (none if it does not exist); a damaged file is moved aside."""
    try:
        data = path.read_bytes() if path.stat().st_size <= _MAX_BYTES else None
    except FileNotFoundError:
        return Loaded()
    except OSError as exc:
        return Loaded(note=f"{path}: cannot read ({exc.strerror or exc}); starting without tombstones")
    try:
        if data is None:
            raise ValueError(f"larger than {_MAX_BYTES} bytes")
        kept = _decode(data)
    except (msgspec.DecodeError, msgspec.ValidationError, ValueError) as exc:
        return Loaded(note=_set_aside(path, now, str(exc)))
    return Loaded({uid: t for uid, t in kept.items() if t.until > now})


def _set_aside(path: Path, now: float, reason: str) -> str:
    aside = path.with_name(f"{path.name}.corrupt-{int(now)}")
    try:
        os.replace(path, aside)
        where = f"moved aside to {aside.name}"
    except OSError as exc:
        where = f"cannot move it aside: {exc.strerror or exc}"
    return f"{path}: unreadable ({reason[:120]}); {where}; starting without tombstones"


def save(path: Path, tombstones: dict[str, Tombstone]) -> str | None:
    """Write ``tombstones`` to ``path`` atomically; returns None, or one line saying why not."""
    data = msgspec.json.encode(
        {uid: (t.after, t.until, t.source[:MAX_SOURCE_CHARS]) for uid, t in tombstones.items()}
    )
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        private_dir(path.parent)  # the mission's state: its owner's only (0700, the file 0600)
        with open(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, FILE_MODE), "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        return f"{path}: cannot save tombstones ({exc.strerror or exc})"
    return None


class Keeper:
    """Keeps a bridge's tombstones in ``path``: ``restore`` once at the start, ``keep`` after each step.

    ``keep`` writes only when the tombstones changed (``BridgeState.tombstones_version``);
    a failure to write is logged once, the tombstones stay in memory, and the next change tries again.
    """

    def __init__(self, path: Path, log: Callable[[str], None]) -> None:
        self.path, self.log = path, log
        self._saved = -1
        self._failing = False

    def restore(self, state: BridgeState, now: float) -> int:
        """Put the file's tombstones into ``state``; returns how many it holds now."""
        loaded = load(self.path, now)
        if loaded.note:
            self.log(loaded.note)
        state.restore_tombstones(loaded.tombstones, now)
        self._saved = state.tombstones_version
        return len(state.tombstones)

    def keep(self, state: BridgeState) -> None:
        if state.tombstones_version == self._saved:
            return
        self._saved = state.tombstones_version
        note = save(self.path, state.tombstones)
        if note is not None and not self._failing:
            self.log(note)
        self._failing = note is not None
