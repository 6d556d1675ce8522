"""YAML as people write it: PyYAML's safe loader, with YAML 1.2 floats.

PyYAML follows YAML 1.1, where ``1e3`` and ``2.5e-1`` without a sign on the
exponent's mantissa are *strings*; a scenario with ``sigma_range: 1e3`` would
then fail with "expected float, got str".  This loader reads them as numbers.
Every YAML file of the project (scenarios, team files, inject scripts) goes
through here.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

__all__ = ["Loader", "compose", "load"]


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
