"""The threat shapes, one registry keyed by the wire's shape name.

A new shape is one module in this package defining a ``ThreatShape``
(``base``) and one entry in ``_REGISTERED`` below: translation from the wire,
the map's outlines and marks, its panel, ``pfp status`` and the TAK remarks
all ask the registry.  A message without a ``shape`` is ``DEFAULT``.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from pfp_service.core.shapes import area, skew_normal
from pfp_service.core.shapes.base import (
    Param,
    ShapeError,
    ThreatShape,
    check_params,
    evaluate,
    level_ring,
    reach_box,
)

__all__ = [
    "DEFAULT",
    "SHAPES",
    "Param",
    "ShapeError",
    "ThreatShape",
    "check_params",
    "evaluate",
    "get",
    "level_ring",
    "reach_box",
]

_REGISTERED: tuple[ThreatShape, ...] = (skew_normal.SHAPE, area.SHAPE)

SHAPES: Mapping[str, ThreatShape] = MappingProxyType({s.name: s for s in _REGISTERED})
DEFAULT = skew_normal.SHAPE.name


def get(name: str) -> ThreatShape:
    """The shape named ``name``.

    Raises:
        ShapeError: ``"shape: ..."`` naming the shapes there are.
    """
    shape = SHAPES.get(name)
    if shape is None:
        raise ShapeError(f"shape: unknown threat shape {name!r} (known: {', '.join(SHAPES)})")
    return shape
