"""Untrusted files read within stated bounds: the one table of limits, and the checks that enforce them.

Every file a user or an attacker can name (scenario, team, inject script, zones
GeoJSON, the planner's TOML, a recording) is checked against ``LIMITS`` before
the expensive work: the size before reading, the nesting depth and the count of
positions of JSON and TOML by a byte scan before parsing, and YAML's depth and
nodes (aliases counted every time they are used) from the parser's events
before a single node is built.  A refusal is an ``InputError`` naming the file
and the limit, so a CLI prints one line and exits 2.  ``docs/operations.md``
shows ``table()``; tests/unit/test_bounds.py keeps the two the same.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from pfp_service.errors import InputError

__all__ = [
    "LIMITS",
    "Limit",
    "check_depth",
    "json_line_of",
    "scan_json",
    "scan_toml",
    "table",
]


@dataclass(frozen=True)
class Limit:
    """One bound: its value, what it counts, the files it applies to, and why it is what it is."""

    value: int
    counts: str
    files: str
    why: str


MiB = 1024 * 1024
# name -> Limit; the code reads the values from here, and the docs table is made from it.
LIMITS: dict[str, Limit] = {
    "text_bytes": Limit(
        16 * MiB,
        "bytes of a text file",
        "every text file (TOML, JSON, GeoJSON, YAML)",
        "a team of 10,000 units is about 2 MiB",
    ),
    "yaml_bytes": Limit(
        1 * MiB,
        "bytes of a YAML file",
        "scenario, team, inject script",
        "PyYAML builds about 0.5 MiB of nodes a second; a 1,000-unit team is 80 KiB",
    ),
    "yaml_nodes": Limit(
        50_000,
        "YAML nodes, each alias counted as the whole node it stands for",
        "scenario, team, inject script",
        "bounds an alias bomb, and the time to build and check the document (about 1 s)",
    ),
    "yaml_aliases": Limit(
        1_000,
        "aliases (`*name`) in a YAML file",
        "scenario, team, inject script",
        "anchors share settings; a thousand uses is far past that",
    ),
    "depth": Limit(
        64,
        "levels of nesting (lists and mappings)",
        "every YAML, JSON, GeoJSON and TOML file",
        "the deepest real file is 6 levels (a zone's rings); deeper ends in a recursion error",
    ),
    "json_positions": Limit(
        65_536,
        "coordinate positions (arrays of numbers) in a JSON file",
        "GeoJSON zones (`--zones`), JSON scenarios",
        "16 zones of the wire's 4,096 vertices; about 1 s to localise",
    ),
    "mcap_chunk_bytes": Limit(
        16 * MiB,
        "bytes of one chunk, compressed or declared uncompressed",
        "MCAP (`pfp report`, `pfp replay`)",
        "the recorder writes 1 MiB chunks",
    ),
    "mcap_ratio": Limit(
        200,
        "times a chunk's declared uncompressed size may exceed its compressed size",
        "MCAP",
        "pfp record's zstd chunks are 10-13 times; a decompression bomb is thousands",
    ),
    "mcap_decoded_bytes": Limit(
        512 * MiB,
        "bytes of all chunks' records once decompressed",
        "MCAP",
        "bounds a decompression bomb's memory and time",
    ),
    "mcap_span_s": Limit(
        7 * 86_400,
        "seconds from a recording's first log time to its last (none may be in the future)",
        "MCAP",
        "pfp replay waits out the recorded clock: a far-future time held it until signalled",
    ),
    "mcap_messages": Limit(
        2_000_000,
        "messages read from a recording",
        "MCAP",
        "an hour of 50 units reporting at 10 Hz is 1,800,000",
    ),
    "dem_side_cells": Limit(
        1_048_576,
        "cells along one side of a DEM, as its header declares them",
        "DEM (`pfp terrain`)",
        "half the world's longitudes at 1 arc-second are 648,000; a larger header is a lie",
    ),
    "dem_block_cells": Limit(
        4 * MiB,
        "cells of one stored block (tile or strip) of a DEM",
        "DEM",
        "GDAL decompresses a block whole; real DEMs store 256 x 256 to 1,024 x 1,024 tiles or strips of a few rows",
    ),
    "dem_cells": Limit(
        16 * MiB,
        "cells read from a DEM after cropping to the area asked for (8 bytes each)",
        "DEM",
        "128 MiB of elevations: 40 km x 40 km at 10 m, 16 times a 1,000 x 1,000 viewshed grid",
    ),
}


def table() -> str:
    """``LIMITS`` as the Markdown table docs/operations.md shows."""
    rows = ["| limit | value | counts | applies to | why |", "|---|---|---|---|---|"]
    for name, lim in LIMITS.items():
        value = f"{lim.value // MiB} MiB" if lim.value % MiB == 0 and "bytes" in name else f"{lim.value:,}"
        rows.append(f"| `{name}` | {value} | {lim.counts} | {lim.files} | {lim.why} |")
    return "\n".join(rows) + "\n"


def limit(name: str) -> int:
    """The value of ``LIMITS[name]``."""
    return LIMITS[name].value


def check_depth(obj: Any, source: str) -> None:
    """Refuse a parsed document nested deeper than ``depth`` (walked without recursion).

    Raises:
        InputError: naming ``source`` and the limit.
    """
    most = limit("depth")
    todo: list[tuple[Any, int]] = [(obj, 0)]
    while todo:
        node, level = todo.pop()
        if level > most:
            raise _too_deep(source)
        if isinstance(node, dict):
            todo.extend((v, level + 1) for v in node.values())
        elif isinstance(node, list | tuple):
            todo.extend((v, level + 1) for v in node)


def _too_deep(source: str) -> InputError:
    return InputError(source, f"nested deeper than {limit('depth')} levels (depth)")


_QUOTED = re.compile(rb'"[^"]*"')
# TOML: multi-line and single-line basic and literal strings, and comments
_TOML_SKIP = re.compile(rb'"""[\s\S]*?"""|\'\'\'[\s\S]*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*')
_NOT_STRUCTURE = bytes(b for b in range(256) if b not in b"[]{}-0123456789")
_NOT_STRUCTURE_OR_QUOTE = bytes(b for b in range(256) if b not in b'"[]{}-0123456789')
_DIGITS = b"-0123456789"


def _max_depth(brackets: bytes) -> int:
    """The deepest nesting of a string of only ``[]{}``."""
    import numpy as np

    if not brackets:
        return 0
    a = np.frombuffer(brackets, dtype=np.uint8)
    step = np.where((a == ord("[")) | (a == ord("{")), 1, -1).astype(np.int32)
    return int(np.cumsum(step).max())


def scan_json(data: bytes | str, source: str, positions: int | None = None) -> None:
    """Refuse JSON nested deeper than ``depth`` or, given ``positions``, with more numeric arrays than it.

    A byte scan (strings blanked, then everything but brackets and digits dropped), so it
    costs a few passes in C over the file, never a parse.

    Raises:
        InputError: naming ``source`` and the limit.
    """
    raw = data.encode() if isinstance(data, str) else data
    # Escaped backslashes, then escaped quotes, go first: what is left of a string is its quotes and
    # the structure bytes in it, dropped by a regex over the (much smaller) squashed bytes.
    # Removing '""' then drops an empty string, or joins two strings that were side by side.
    squashed = raw.replace(b"\\\\", b"").replace(b'\\"', b"").translate(None, _NOT_STRUCTURE_OR_QUOTE)
    del raw
    _check_squashed(_QUOTED.sub(b"", squashed.replace(b'""', b"")), source, positions)


def scan_toml(data: bytes | str, source: str) -> None:
    """Refuse TOML whose arrays and inline tables nest deeper than ``depth`` (table headers count one or two).

    Raises:
        InputError: naming ``source`` and the limit.
    """
    raw = data.encode() if isinstance(data, str) else data
    _check_squashed(_TOML_SKIP.sub(b"", raw).translate(None, _NOT_STRUCTURE), source, None)


def _check_squashed(squashed: bytes, source: str, positions: int | None) -> None:
    if positions is not None:
        # a position is an array whose first item is a number: "[" then a digit or "-"
        found = sum(squashed.count(b"[" + bytes([d])) for d in _DIGITS)
        if found > positions:
            raise InputError(
                source, f"holds {found:,} positions; the limit is {positions:,} (json_positions)"
            )
    if _max_depth(squashed.translate(None, _DIGITS)) > limit("depth"):
        raise _too_deep(source)


_JSON_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{},:]|-?[0-9][0-9.eE+-]*|true|false|null')
_SEGMENT = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def json_line_of(text: str, path: str) -> int | None:
    """The 1-based line of the value at ``path`` (``features[2].geometry``) in JSON ``text``, or of its
    nearest parent; one pass over the tokens, without building the document.
    """
    import json

    want: list[str | int] = [int(i) if i else name for name, i in _SEGMENT.findall(path)]
    stack: list[list[Any]] = []  # [kind, segment, expecting a key]
    best, best_len = None, -1

    def reached(pos: int) -> bool:
        nonlocal best, best_len
        here = [f[1] for f in stack]
        if len(here) > best_len and here == want[: len(here)]:
            best, best_len = text.count("\n", 0, pos) + 1, len(here)
        return best_len == len(want)

    for m in _JSON_TOKEN.finditer(text):
        tok = m.group()
        top = stack[-1] if stack else None
        if tok in ("{", "["):
            if reached(m.start()):
                return best
            stack.append([tok, 0 if tok == "[" else None, tok == "{"])
        elif tok in ("}", "]"):
            if stack:
                stack.pop()
        elif tok == ",":
            if top is not None:
                if top[0] == "[":
                    top[1] += 1
                else:
                    top[2] = True
        elif tok == ":":
            continue
        elif top is not None and top[0] == "{" and top[2] and tok.startswith('"'):
            try:
                top[1] = json.loads(tok)
            except ValueError:
                top[1] = tok
            top[2] = False
        elif reached(m.start()):
            return best
    return best
