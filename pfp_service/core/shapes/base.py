"""What a threat shape is: the ``ThreatShape`` protocol, its parameters, and what every shape shares.

A shape is a kind of threat as the wire names it (``ThreatUpdate.shape``).  It
declares its parameters (``Param``: name, unit, bounds, default), maps them to
the core ``Threat`` (a location, a scale matrix, a skew vector and a weight:
the one form ``kernels.pack_row`` packs, so the compiled hot path never
branches on a shape), and says how a client draws it (``outline``, ``marks``)
and describes it (``describe``).

What the packed form already gives every shape is here once: its value and
exact gradient (``evaluate``, the kernels'), its box of influence for culling
(``reach_box``, ``cull.influence_boxes``'), and the outline of a level set
traced by bisection (``level_ring``), which a shape with a closed form may
replace.  Line of sight over terrain (``core.visibility``) masks every shape
alike, after packing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from pfp_service.core.options import Intensity

if TYPE_CHECKING:  # the kernels compile on first use: describing a shape needs none
    from pfp_service.core.threat import Threat

__all__ = [
    "Param",
    "Point",
    "Polyline",
    "ShapeError",
    "ThreatShape",
    "check_params",
    "evaluate",
    "level_ring",
    "reach_box",
]

Point = tuple[float, float]
Polyline = list[Point]
_BISECTIONS = 60  # halvings of the first bracket: far below a millimetre at any spread


class ShapeError(ValueError):
    """A shape the registry lacks, or parameters a shape refuses: ``"<field>: <reason>"``.

    A refusal of the input, where any other exception from a shape is a fault.
    """


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter of a shape, as given on the wire.

    Attributes:
        name: its key (``params.<name>`` on the wire), with its unit in the name.
        lo, hi: inclusive bounds.
        default: its value when absent; ``None`` makes it required.
        doc: one line saying what it is, for the docs.
    """

    name: str
    lo: float
    hi: float
    default: float | None = None
    doc: str = ""


class ThreatShape(Protocol):
    """A kind of threat: its parameters, its packed form, how it is drawn and described."""

    @property
    def name(self) -> str:
        """Its name on the wire, the registry's key."""

    @property
    def summary(self) -> str:
        """One line saying what kind of enemy it models."""

    @property
    def params(self) -> tuple[Param, ...]:
        """Its parameters, in the order ``describe`` gives them."""

    def threat(self, position: Point, params: Mapping[str, float], weight: float, threat_id: str) -> Threat:
        """The core form the kernels pack, from parameters ``check_params`` has passed."""

    def outline(self, threat: Threat, fraction: float, vertices: int) -> Polyline:
        """The ring where the threat's own level is ``fraction`` of its peak, in metres, counter-clockwise."""

    def marks(self, position: Point, params: Mapping[str, float]) -> list[Polyline]:
        """Lines a client draws beside the outline (a facing arrow), in metres; none for most shapes."""

    def describe(self, params: Mapping[str, float]) -> list[tuple[str, str]]:
        """``(label, value)`` rows for a panel, a status line or a TAK remark."""


def check_params(shape: ThreatShape, given: Mapping[str, float]) -> dict[str, float]:
    """``given`` with the defaults filled in, refused unless every name is known and every value in bounds.

    Raises:
        ShapeError: ``"params.<name>: <reason>"``, the field first as every wire rejection.
    """
    known = {p.name: p for p in shape.params}
    for name in given:
        if name not in known:
            raise ShapeError(
                f"params.{name}: not a parameter of the {shape.name} shape (it takes {sorted(known)})"
            )
    out: dict[str, float] = {}
    for p in shape.params:
        v = given.get(p.name, p.default)
        if v is None:
            raise ShapeError(f"params.{p.name}: is required by the {shape.name} shape")
        v = float(v)
        if not (math.isfinite(v) and p.lo <= v <= p.hi):
            raise ShapeError(f"params.{p.name}: must be within [{p.lo:g}, {p.hi:g}], got {v!r}")
        out[p.name] = v
    return out


def evaluate(
    threat: Threat, points: np.ndarray, intensity: Intensity = "peak"
) -> tuple[np.ndarray, np.ndarray]:
    """One threat's level ``(N,)`` and exact gradient ``(N, 2)`` at ``points`` ``(N, 2)``: the kernels' own."""
    from pfp_service.core.threat import ThreatField

    return ThreatField([threat], intensity).level_grad(points)


def reach_box(threat: Threat) -> tuple[float, float, float, float]:
    """``(x0, y0, x1, y1)`` outside which culling leaves this threat out (``cull.influence_boxes``)."""
    from pfp_service.core.cull import influence_boxes
    from pfp_service.core.threat import ThreatField

    x0, y0, x1, y1 = influence_boxes(ThreatField([threat]).packed)[0]
    return float(x0), float(y0), float(x1), float(y1)


def level_ring(t: Threat, level: float, vertices: int) -> np.ndarray:
    """The boundary of ``{x : t(x) >= level * max t}`` as ``(vertices, 2)`` metres, counter-clockwise from east.

    Bisects along a fan of rays from the peak (``Threat.mode``) on the cores'
    level ratio; a log-concave density crosses each ray once.

    Raises:
        ValueError: ``level`` outside (0, 1) or a weightless threat (it has no zone).
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level: must be strictly between 0 and 1, got {level}")
    if not t.weight > 0.0:
        raise ValueError(f"threat {t.id!r}: a threat of weight 0 has no zone")
    from pfp_service.core.cores import Cores
    from pfp_service.core.threat import ThreatField

    cores = Cores(ThreatField([t]))
    mx, my = t.mode()
    theta = 2.0 * math.pi * np.arange(vertices) / vertices
    d = np.column_stack([np.cos(theta), np.sin(theta)])
    (o00, _), (_, o11) = t.omega
    lo = np.zeros(vertices)
    hi = np.full(vertices, math.sqrt(max(o00, o11)))
    for _ in range(64):  # grow until every ray has left the zone; a Gaussian tail does within ~10 sigma
        outside = cores.ratio(np.array([mx, my]) + hi[:, None] * d)[0] < level
        if outside.all():
            break
        hi = np.where(outside, hi, 2.0 * hi)
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        inside = cores.ratio(np.array([mx, my]) + mid[:, None] * d)[0] >= level
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    r = 0.5 * (lo + hi)
    return np.asarray(np.array([mx, my]) + r[:, None] * d)


def rounded(ring: Sequence[Sequence[float]] | np.ndarray) -> Polyline:
    """A ring or line to the millimetre, as plain floats (what the map feed carries)."""
    return [(round(float(x), 3), round(float(y), 3)) for x, y in ring]
