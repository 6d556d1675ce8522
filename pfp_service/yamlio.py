"""YAML as people write it: PyYAML's safe loader, with YAML 1.2 floats.

PyYAML follows YAML 1.1, where ``1e3`` and ``2.5e-1`` without a sign on the
exponent's mantissa are *strings*; a scenario with ``sigma_range: 1e3`` would
then fail with "expected float, got str".  This loader reads them as numbers.
Every YAML file of the project (scenarios, team files, inject scripts) goes
through here.  ``load_yaml(path, Struct)`` turns a bad file into one
``InputError`` that names the file, the line and the field (``team.yaml line
7, units[2].speed_mps: must be > 0``), so a CLI prints one line and exits 2.

Files are untrusted: before a node is built, one pass over the parser's events
refuses a file nested deeper than ``bounds.LIMITS["depth"]``, with more nodes
than ``yaml_nodes`` (an alias counts as the whole node it names, so an alias bomb
of a few hundred bytes is refused at once), more than ``yaml_aliases`` aliases,
or an alias to a node still open (a recursive one).  The document is then
composed once, by libyaml when it is there, and built from that node tree.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import msgspec
import yaml

from pfp_service.bounds import LIMITS
from pfp_service.errors import InputError, from_validation
from pfp_service.files import read_text
from pfp_service.geo import localise_document

__all__ = ["Loader", "check", "compose", "line_of", "load", "load_yaml", "located", "parse"]

T = TypeVar("T")


_Base: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's parser and composer when built with it


class Loader(_Base):  # type: ignore[misc]
    """``yaml.SafeLoader`` (libyaml's when present) plus the YAML 1.2 core schema's float forms."""


_FLOAT = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""",
    re.X,
)
Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))


def check(text: str | bytes, source: str = "") -> None:
    """Refuse a document past the YAML bounds (``bounds.LIMITS``), from its events, before any node is built.

    Raises:
        InputError: naming ``source``, the line and the limit.
        yaml.YAMLError: the text is not YAML (found while reading the events).
    """
    size = len(text.encode() if isinstance(text, str) else text)
    if size > LIMITS["yaml_bytes"].value:
        raise InputError(
            source, f"{size:,} bytes of YAML; the limit is {LIMITS['yaml_bytes'].value:,} (yaml_bytes)"
        )
    most_depth, most_nodes, most_aliases = (LIMITS[n].value for n in ("depth", "yaml_nodes", "yaml_aliases"))
    depth = nodes = aliases = 0
    sizes: dict[str, int] = {}  # anchor -> nodes it stands for, once its node is complete
    open_: list[tuple[str | None, int]] = []  # (anchor, nodes before it) of each open collection
    for ev in _events(text, source, most_depth):
        if isinstance(ev, yaml.CollectionStartEvent):
            depth += 1
            if depth > most_depth:
                raise _refuse(source, ev, f"nested deeper than {most_depth} levels (depth)")
            open_.append((ev.anchor, nodes))
            nodes += 1
        elif isinstance(ev, yaml.CollectionEndEvent):
            depth -= 1
            anchor, before = open_.pop()
            if anchor is not None:
                sizes[anchor] = nodes - before
        elif isinstance(ev, yaml.ScalarEvent):
            nodes += 1
            if ev.anchor is not None:
                sizes[ev.anchor] = 1
        elif isinstance(ev, yaml.AliasEvent):
            aliases += 1
            if aliases > most_aliases:
                raise _refuse(source, ev, f"more than {most_aliases:,} aliases (yaml_aliases)")
            if ev.anchor not in sizes:
                raise _refuse(
                    source, ev, f"alias *{ev.anchor} names no complete node (undefined or recursive)"
                )
            nodes += sizes[ev.anchor]
        if nodes > most_nodes:
            raise _refuse(
                source,
                ev,
                f"more than {most_nodes:,} nodes, each alias counted as what it names (yaml_nodes)",
            )


def _events(text: str | bytes, source: str, most_depth: int) -> Iterator[yaml.Event]:
    """The parser's events; libyaml's own nesting limit (1,000 flow levels) reported as ours."""
    try:
        yield from yaml.parse(text, Loader=Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        if "nesting depth" not in str(getattr(exc, "problem", "")) or mark is None:
            raise
        where = f"{source} line {mark.line + 1}".strip()
        raise InputError(where, f"nested deeper than {most_depth} levels (depth)") from None


def _refuse(source: str, ev: yaml.Event, reason: str) -> InputError:
    mark = ev.start_mark
    where = f"line {mark.line + 1}" if mark is not None else ""
    return InputError(f"{source} {where}".strip(), reason)


def parse(text: str | bytes, source: str = "") -> tuple[Any, yaml.Node | None]:
    """One YAML document within the bounds: its value and its node tree (for line numbers).

    Raises:
        InputError: past a bound (``check``).
        yaml.YAMLError: not YAML.
    """
    check(text, source)
    loader = Loader(text)
    try:
        root = loader.get_single_node()
        return (None if root is None else loader.construct_document(root)), root
    finally:
        loader.dispose()


def load(text: str | bytes, source: str = "") -> Any:
    """Parse one YAML document within the bounds (raises ``InputError`` past one, ``yaml.YAMLError``)."""
    return parse(text, source)[0]


def compose(text: str | bytes, source: str = "") -> yaml.Node | None:
    """The node tree of one YAML document within the bounds, for line numbers (raises as ``load``)."""
    check(text, source)
    return yaml.compose(text, Loader=Loader)


_SEGMENT = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def line_of(root: yaml.Node | None, path: str) -> int | None:
    """The 1-based line of the YAML node at ``path`` (``timeline[3].position``), or its nearest parent."""
    node = root
    line = None if node is None else node.start_mark.line + 1
    for name, index in _SEGMENT.findall(path):
        nxt = None
        if index and isinstance(node, yaml.SequenceNode) and int(index) < len(node.value):
            nxt = node.value[int(index)]
        elif name and isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                if getattr(k, "value", None) == name:
                    nxt = v if not isinstance(v, yaml.ScalarNode) else k
                    break
        if nxt is None:
            break
        node = nxt
        line = node.start_mark.line + 1
    return line


def load_yaml(
    path: str | Path,
    cls: type[T],
    choices: dict[str, tuple[str, ...]] | None = None,
    prepare: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
) -> tuple[T, yaml.Node | None]:
    """Read and validate a YAML file as ``cls``; returns the value and the node tree (for line numbers).

    ``prepare`` turns what ``localise_document`` does not know into metres first (a script's zones).

    Raises:
        InputError: unreadable file, invalid YAML or an invalid field, with its line.
    """
    p = Path(path)
    text = read_text(p, LIMITS["yaml_bytes"].value)
    try:
        obj, root = parse(text, p.name)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{p.name} line {mark.line + 1}" if mark is not None else p.name
        raise InputError(where, f"invalid YAML: {getattr(exc, 'problem', None) or exc}") from None
    if not isinstance(obj, dict):
        raise InputError(p.name, f"expected a mapping at the top, got {type(obj).__name__}")
    try:
        if prepare is not None:
            obj = prepare(obj)
        obj = localise_document(obj)  # {lat, lon} positions to metres from the file's origin
    except InputError as bad:
        raise located(p, root, bad) from None
    try:
        return msgspec.convert(obj, cls), root
    except msgspec.ValidationError as exc:
        err = from_validation(exc, choices)
        name = err.path.rsplit(".", 1)[-1]
        if err.reason.startswith("invalid value") and name in (choices or {}):
            err = InputError(err.path, f"{err.reason} (expected one of: {', '.join((choices or {})[name])})")
        raise located(p, root, err) from None


def located(path: Path, root: yaml.Node | None, err: InputError) -> InputError:
    """``err`` with the file name and the line of its field prefixed to the path."""
    line = line_of(root, err.path)
    where = f"{path.name} line {line}" if line is not None else path.name
    return InputError(f"{where}, {err.path}" if err.path else where, err.reason)
