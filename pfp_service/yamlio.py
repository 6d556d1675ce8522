"""YAML as people write it: PyYAML's safe loader, with YAML 1.2 floats.

PyYAML follows YAML 1.1, where ``1e3`` and ``2.5e-1`` without a sign on the
exponent's mantissa are *strings*; a scenario with ``sigma_range: 1e3`` would
then fail with "expected float, got str".  This loader reads them as numbers.
Every YAML file of the project (scenarios, team files, inject scripts) goes
through here.  ``load_yaml(path, Struct)`` turns a bad file into one
``InputError`` that names the file, the line and the field (``team.yaml line
7, units[2].speed_mps: must be > 0``), so a CLI prints one line and exits 2.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import msgspec
import yaml

from pfp_service.errors import InputError, from_validation
from pfp_service.files import read_text
from pfp_service.geo import localise_document

__all__ = ["Loader", "compose", "line_of", "load", "load_yaml", "located"]

T = TypeVar("T")


class Loader(yaml.SafeLoader):
    """``yaml.SafeLoader`` plus the YAML 1.2 core schema's float forms."""


_FLOAT = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""",
    re.X,
)
Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))


def load(text: str | bytes) -> Any:
    """Parse one YAML document (raises ``yaml.YAMLError``)."""
    return yaml.load(text, Loader=Loader)


def compose(text: str | bytes) -> yaml.Node | None:
    """The node tree of one YAML document, for line numbers (raises ``yaml.YAMLError``)."""
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
    text = read_text(p)
    try:
        root = compose(text)
        obj = load(text)
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
