"""The one place the wire and the core meet: a message becomes a core value, a core value a reply.

The wire imports no core and the core no wire (import-linter's contracts hold
both without exceptions), so whatever turns one into the other lives here:
a ``ThreatUpdate`` into a core ``Threat`` through its shape (``threat``), a ``ZoneUpdate`` into a
core ``Zone`` (``zone``), and the preview reply, which is the core's
``PlanResult`` itself, into bytes (``fit_reply``) and back
(``decode_plan_result``).  ``supplied()`` gives the wire's contract generator
(``wire.schema.render``) the preview reply's type and example, which the wire
cannot name.

The core is imported where it is used, as the wire did before: a client or a
command that reads a hostile file imports this module without compiling the
core's kernels (tests/proc/test_light_commands.py).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import msgspec

from pfp_service.core import shapes
from pfp_service.core.shapes import ShapeError
from pfp_service.errors import InputError
from pfp_service.wire import MAX_PAYLOAD_BYTES, ThreatUpdate, decode, encode
from pfp_service.wire.messages import ZoneUpdate
from pfp_service.wire.messages.structs import DEFAULT_SHAPE

if TYPE_CHECKING:
    from pfp_service.core.plan import PlanResult
    from pfp_service.core.threat import Threat
    from pfp_service.core.zones import Zone
    from pfp_service.wire.schema import Supplied  # the contract builds its examples (shapely) on import

__all__ = [
    "ShapeError",
    "check",
    "decode_plan_result",
    "describe",
    "fit_reply",
    "refusal",
    "shape_params",
    "supplied",
    "threat",
    "zone",
]


def threat(update: ThreatUpdate, threat_id: str) -> Threat:
    """The core's ``Threat`` for ``update``, named ``threat_id``, through its shape (``core.shapes``).

    Raises:
        ShapeError: ``"<field>: <reason>"`` (a ``ValueError``): a shape the planner
            does not know, or parameters its shape refuses.
    """
    shape, params = _checked(update)
    try:
        return shape.threat(update.position, params, update.weight, threat_id)
    except ShapeError as exc:
        raise _named(update, exc) from exc


def check(update: ThreatUpdate) -> None:
    """Refuse ``update`` as ``threat`` would for its shape and parameters, without the compiled core.

    For readers of files (a script, a scenario) that refuse a threat when they load it.

    Raises:
        ShapeError: as ``threat``.
    """
    _checked(update)


def _checked(update: ThreatUpdate) -> tuple[shapes.ThreatShape, dict[str, float]]:
    try:
        shape = shapes.get(update.shape)
        return shape, shapes.check_params(shape, shape_params(update))
    except ShapeError as exc:
        raise _named(update, exc) from exc


def _named(update: ThreatUpdate, exc: ShapeError) -> ShapeError:
    """The refusal with the field as the message names it: the skew-normal's are top-level."""
    return exc if update.shape != DEFAULT_SHAPE else ShapeError(str(exc).removeprefix("params."))


def shape_params(update: ThreatUpdate) -> dict[str, float]:
    """The parameters ``update`` gives its shape: the skew-normal's are its top-level fields, as before shapes."""
    if update.shape != DEFAULT_SHAPE:
        return dict(update.params or {})
    assert update.sigma_range is not None and update.sigma_lateral is not None  # the decoder's check
    return {
        "facing_deg": update.facing_deg,
        "sigma_range": update.sigma_range,
        "sigma_lateral": update.sigma_lateral,
        "skew": update.skew,
    }


def refusal(exc: ShapeError, prefix: str = "$") -> InputError:
    """A shape's refusal (``"<field>: <reason>"``) as the wire's, its field under ``prefix``."""
    field, _, reason = str(exc).partition(": ")
    return InputError(f"{prefix}.{field}", reason)


def describe(update: ThreatUpdate) -> list[tuple[str, str]]:
    """``(label, value)`` rows of a threat's shape and parameters, for a panel, a status line or a remark.

    Raises:
        ValueError: as ``threat``.
    """
    shape, params = _checked(update)
    return [("shape", shape.name), *shape.describe(params)]


def zone(update: ZoneUpdate, zone_id: str) -> Zone:
    """The core's ``Zone`` for ``update``, named ``zone_id`` (its positions already in metres).

    Raises:
        ValueError: a zone the decoder passed that the core still refuses.
    """
    from pfp_service.core.zones import Zone

    if update.circle is not None:
        return Zone.circle(zone_id, update.circle.centre, update.circle.radius_m, update.kind)
    rings = update.polygon or []
    return Zone.polygon(zone_id, rings[0], rings[1:], update.kind)


def decode_plan_result(data: bytes | bytearray | memoryview | None) -> PlanResult:
    """A preview reply: the core's ``PlanResult``, exactly what ``pfp plan --json`` prints.

    Raises:
        InputError: ``path`` rooted at ``$`` and the reason (as every wire decoder).
    """
    from pfp_service.core.plan import PlanResult

    return decode(PlanResult, data)


def fit_reply(result: PlanResult, limit: int = MAX_PAYLOAD_BYTES) -> bytes:
    """The reply bytes, within ``limit``: the path (and its elevations, over terrain) is thinned (ends kept)
    and marked if it must be."""
    data = encode(result)
    path, heights = result.path, result.path_elevation_m
    keep = len(path)
    while len(data) > limit and keep > 2:
        keep = max(2, int(keep * 0.9 * limit / len(data)))
        stride = (len(path) - 1) / (keep - 1)
        idx = [round(i * stride) for i in range(keep - 1)] + [len(path) - 1]
        thinned = [path[i] for i in idx]
        elevations = (
            [heights[i] for i in idx] if heights is not None and len(heights) == len(path) else heights
        )
        data = encode(
            msgspec.structs.replace(result, path=thinned, path_elevation_m=elevations, path_decimated=True)
        )
    return data


def supplied() -> dict[str, Supplied]:
    """The contract's messages whose type is the core's, for ``wire.schema.render``: the preview reply."""
    from pfp_service.core.plan import PlanResult, PlanStatus, UsedParams
    from pfp_service.wire.schema import Supplied

    example = PlanResult(
        status=PlanStatus.REACHED,
        reason="within tolerance of the goal",
        steps=2,
        length=0.2,
        exposure=0.0015,
        peak_threat=0.0081,
        min_clearance=6.3,
        final_distance=0.05,
        path=[(9.85, 9.85), (9.92, 9.92), (9.99, 9.99)],
        compute_ms=0.4,
        params=UsedParams(delta=1.0, step=0.1, max_iter=300, tolerance=0.1, intensity="peak", escape="none"),
    )
    return {"preview_reply": Supplied(PlanResult, (("preview_reply", example),))}
