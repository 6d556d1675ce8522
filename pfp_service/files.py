"""Reading the text files people name on the command line, with one clear error for each way it fails.

A missing file, a directory, a device that never ends, a binary or
non-UTF-8 file and a file too large to be a configuration all become one
``InputError`` naming the file, so a CLI prints one line and exits 2.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from pfp_service.bounds import LIMITS
from pfp_service.errors import InputError

__all__ = ["MAX_TEXT_BYTES", "read_text"]

MAX_TEXT_BYTES = LIMITS["text_bytes"].value


def read_text(path: str | Path, max_bytes: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of a regular file.

    Raises:
        InputError: path ``str(path)``; cannot read, not a regular file, larger than
            ``max_bytes``, a NUL byte (binary) or not UTF-8 (with the byte offset).
    """
    p = Path(path)
    name = str(p)
    try:
        with open(p, "rb") as f:
            mode = os.fstat(f.fileno()).st_mode
            if stat.S_ISDIR(mode):
                raise InputError(name, "is a directory, not a file")
            if not stat.S_ISREG(mode):
                raise InputError(name, "is not a regular file")
            data = f.read(max_bytes + 1)
    except IsADirectoryError:
        raise InputError(name, "is a directory, not a file") from None
    except OSError as exc:
        raise InputError(name, f"cannot read: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        which = next((n for n, lim in LIMITS.items() if n.endswith("_bytes") and lim.value == max_bytes), "")
        raise InputError(name, f"larger than {max_bytes:,} bytes, the limit for this kind of file ({which})")
    if b"\x00" in data:
        raise InputError(name, "is a binary file (it holds NUL bytes), not text")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(name, f"is not UTF-8 text (byte {exc.start} is 0x{data[exc.start]:02x})") from None
