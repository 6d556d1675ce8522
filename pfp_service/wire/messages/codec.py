"""Encoding and decoding: the only way a payload comes in (``decode_*``) or goes out (``encode``).

Every decoder checks the size, the types and every bound, and raises
``InputError`` whose ``path`` is rooted at ``$``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from typing import Any, TypeVar

import msgspec

from pfp_service.errors import InputError, from_validation
from pfp_service.geo import MAX_RANGE_M, LatLon, localise
from pfp_service.wire.messages.events import (
    EVENT_KINDS,
    AnyEvent,
    ArrivedEvent,
    Event,
    TrappedEvent,
)
from pfp_service.wire.messages.structs import (
    CHOICES,
    MAX_PAYLOAD_BYTES,
    MAX_WHATIF_THREATS,
    MAX_WORLD_QUERY_CHARS,
    MAX_ZONE_RINGS,
    MAX_ZONE_VERTICES,
    Bounds,
    Direction,
    ErrorReply,
    Goal,
    Origin,
    PlannerStatus,
    PreviewRequest,
    ThreatUpdate,
    UnitState,
    ZoneUpdate,
    fit_text,
)
from pfp_service.wire.messages.teams import TeamUpdate
from pfp_service.wire.messages.world import (
    Mission,
    WorldQuery,
    WorldSnapshot,
)

__all__ = [
    "check_bounds",
    "check_extent",
    "decode",
    "decode_direction",
    "decode_error_reply",
    "decode_event",
    "decode_goal",
    "decode_mission",
    "decode_planner_status",
    "decode_preview_request",
    "decode_team",
    "decode_threat",
    "decode_unit_state",
    "decode_world_query",
    "decode_world_snapshot",
    "decode_zone",
    "encode",
    "localise_zone",
]


# -- encoding and decoding -------------------------------------------------------
_ENCODER = msgspec.json.Encoder()
_DECODERS: dict[Any, msgspec.json.Decoder[Any]] = {
    t: msgspec.json.Decoder(t)
    for t in (
        UnitState,
        Goal,
        ThreatUpdate,
        PreviewRequest,
        Direction,
        ErrorReply,
        PlannerStatus,
        AnyEvent,
        WorldSnapshot,
        Mission,
        ZoneUpdate,
        TeamUpdate,
    )
}
M = TypeVar("M")


def encode(msg: msgspec.Struct) -> bytes:
    """JSON bytes of any wire message (or of any other msgspec Struct: the core's ``PlanResult``)."""
    return _ENCODER.encode(msg)


def _rooted(path: str) -> str:
    if not path:
        return "$"
    return "$" + path if path.startswith("[") else "$." + path


_ROOT_OWN = re.compile(r"^(?P<path>[A-Za-z_][\w\[\].]*): (?P<reason>.+)$", re.S)


def _wire_error(exc: msgspec.ValidationError | msgspec.DecodeError) -> InputError:
    text = str(exc)
    # A __post_init__ check of the top-level struct comes without " - at `$`";
    # from_validation would call it malformed JSON.
    own = _ROOT_OWN.match(text) if isinstance(exc, msgspec.ValidationError) else None
    if own is not None and " - at `$" not in text:
        return InputError(_rooted(own["path"]), own["reason"])
    e = from_validation(exc, CHOICES)
    reason = e.reason
    if reason == "number out of range":  # 1e999 and friends: JSON has no infinities
        reason = "expected a finite number"
    elif reason.startswith("expected float, got "):
        reason = "expected a finite number, got " + reason[len("expected float, got ") :]
    elif reason.startswith("expected float | null, got "):
        reason = "expected a finite number or null, got " + reason[len("expected float | null, got ") :]
    return InputError(_rooted(e.path), reason)


# The most lat/lon positions an inbound message holds.  The lat/lon path walks the
# document in Python, on a Zenoh callback thread (docs/operations.md, "Figures behind
# the code's choices"), so for these types a payload with more positions, or more JSON objects and
# arrays than that many positions need, is refused before it is walked.
_GEO_MAX_POSITIONS: dict[Any, int] = {
    UnitState: 1,
    Goal: 1,
    ThreatUpdate: 1,
    PreviewRequest: 2 + MAX_WHATIF_THREATS,
    ZoneUpdate: MAX_ZONE_VERTICES + MAX_ZONE_RINGS + 1,
}


def _geo_document(cls: Any, data: bytes | bytearray) -> Any:
    """The untyped document for the lat/lon path, costing no more than a real message of ``cls``.

    Raises:
        InputError: more positions, objects or arrays than ``cls`` can hold.
    """
    limit = _GEO_MAX_POSITIONS.get(cls)
    if limit is not None:
        if max(data.count(b'"lat"'), data.count(b'"lon"')) > limit:
            raise InputError("$", f"more lat/lon positions than the {limit} a message of this kind holds")
        if data.count(b"{") + data.count(b"[") > 4 * limit + 16:
            raise InputError("$", f"more JSON objects and arrays than {limit} positions need")
    doc = msgspec.json.decode(data)
    fields = getattr(cls, "__struct_fields__", None)
    if fields is not None and isinstance(doc, dict):  # unknown fields are ignored: never walk them
        doc = {k: v for k, v in doc.items() if k in fields}
    return doc


def decode(
    cls: type[M],
    data: bytes | bytearray | memoryview | None,
    bounds: Bounds | None = None,
    origin: Origin | None = None,
) -> M:
    """Decode and validate one message of type ``cls``.

    A position may be ``[x, y]`` metres or ``{"lat": …, "lon": …}``; the
    second becomes metres from ``origin`` here (``geo.localise``), so what
    comes out is always in metres.

    Args:
        cls: a message Struct of this module, ``AnyEvent``, or another Struct (the core's
            ``PlanResult``: ``world.translate.decode_plan_result``).
        data: the payload as received.
        bounds: the mission bounds, if any; every position must lie within them.
        origin: the mission origin, if any; without one a lat/lon is refused.

    Raises:
        InputError: ``path`` rooted at ``$`` and the reason.
    """
    decoder = _DECODERS.get(cls)
    if decoder is None:
        decoder = _DECODERS[cls] = msgspec.json.Decoder(cls)
    size = 0 if data is None else len(data)
    if size == 0:
        raise InputError("$", "empty payload (expected a JSON object)")
    if size > MAX_PAYLOAD_BYTES:
        raise InputError("$", f"payload of {size} bytes exceeds the limit of {MAX_PAYLOAD_BYTES}")
    try:
        if isinstance(data, memoryview):
            data = data.tobytes()
        if b'"lat"' in data or b'"lon"' in data:  # type: ignore[operator]
            # the slow path only for lat/lon: untyped, localised, then typed with the same paths
            doc = _geo_document(cls, data)  # type: ignore[arg-type]
            doc = localise_zone(doc, origin) if cls is ZoneUpdate else localise(doc, origin, "$")
            msg: M = msgspec.convert(doc, cls)
        else:
            msg = decoder.decode(data)  # type: ignore[arg-type]
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise _wire_error(exc) from exc
    except RecursionError:  # [[[[... or {"a":{"a":... deeper than the decoder's stack
        raise InputError("$", "malformed JSON: nested too deeply") from None
    except InputError:
        raise
    except Exception as exc:  # hostile bytes leave this function as an InputError and nothing else
        raise InputError("$", f"cannot decode: {type(exc).__name__}: {exc}"[:200]) from exc
    if bounds is not None:
        check_bounds(msg, bounds)
    if origin is not None:
        check_extent(msg, MAX_RANGE_M)
    return msg


def _vertex(value: Any, origin: Origin | None, path: str) -> Any:
    """A zone vertex or centre given as ``{lat, lon}`` in metres from ``origin``; anything else as it is."""
    if not (isinstance(value, dict) and ("lat" in value or "lon" in value)):
        return value
    try:
        p = msgspec.convert(value, LatLon)
    except msgspec.ValidationError as exc:
        e = from_validation(exc)
        raise InputError(f"{path}.{e.path}" if e.path else path, e.reason) from exc
    if origin is None:
        raise InputError(path, "a lat/lon position needs a mission origin ({lat, lon}); none is set")
    return list(origin.localise_point(p, path))


def localise_zone(doc: Any, origin: Origin | None, path: str = "$") -> Any:
    """A zone document with its polygon's vertices and circle's centre in metres (``decode``'s lat/lon path).

    Scenario files take their ``zones:`` through here too (``path`` ``zones[i]``).

    Raises:
        InputError: a bad lat/lon, or one without an origin, at its path.
    """
    if not isinstance(doc, dict):
        return doc
    out = dict(doc)
    rings = doc.get("polygon")
    if isinstance(rings, list):
        out["polygon"] = [
            [_vertex(v, origin, f"{path}.polygon[{i}][{k}]") for k, v in enumerate(ring)]
            if isinstance(ring, list)
            else ring
            for i, ring in enumerate(rings)
        ]
    circle = doc.get("circle")
    if isinstance(circle, dict) and "centre" in circle:
        out["circle"] = {**circle, "centre": _vertex(circle["centre"], origin, f"{path}.circle.centre")}
    return out


def _positions(msg: object) -> Iterator[tuple[str, tuple[float, float]]]:
    if isinstance(msg, (UnitState, Goal, ThreatUpdate, TrappedEvent, ArrivedEvent)):
        yield "$.position", msg.position
    elif isinstance(msg, PreviewRequest):
        if msg.start is not None:
            yield "$.start", msg.start
        if msg.goal is not None:
            yield "$.goal", msg.goal
        for i, t in enumerate(msg.threats):
            yield f"$.threats[{i}].position", t.position
    elif isinstance(msg, TeamUpdate) and msg.goal is not None:  # a team's goal, and each place offset from it
        gx, gy = msg.goal.position
        yield "$.goal.position", msg.goal.position
        for u, (dx, dy) in msg.offsets.items():
            yield f"$.offsets.{u}", (gx + dx, gy + dy)


def check_bounds(msg: object, bounds: Bounds) -> None:
    """Check that every position in ``msg`` lies within ``bounds`` (edges included).

    Args:
        msg: a decoded message; those without positions pass.
        bounds: ``((xmin, ymin), (xmax, ymax))`` from the daemon's mission config.

    Raises:
        InputError: the first position outside, with its path.
        ValueError: ``bounds`` is empty or inverted (a configuration bug).
    """
    (x0, y0), (x1, y1) = bounds
    if not (x0 < x1 and y0 < y1):
        raise ValueError(f"bounds: must be ((xmin, ymin), (xmax, ymax)) with min < max, got {bounds}")
    for path, (x, y) in _positions(msg):
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            raise InputError(
                path, f"[{x:g}, {y:g}] lies outside the mission bounds [[{x0:g}, {y0:g}], [{x1:g}, {y1:g}]]"
            )


def check_extent(msg: object, radius_m: float) -> None:
    """Check that every position in ``msg`` lies within ``radius_m`` of the mission origin.

    With an origin the mission is a patch of the earth, and the plane is a map of it only to
    ``geo.MAX_RANGE_M`` (50 km): a goal 7,000 km away, given in metres, is no place on it.

    Raises:
        InputError: the first position beyond, with its path.
    """
    for path, (x, y) in _positions(msg):
        d = math.hypot(x, y)
        if d > radius_m:
            raise InputError(
                path,
                f"[{x:g}, {y:g}] is {d / 1000:,.1f} km from the mission origin; "
                f"the mission's plane reaches {radius_m / 1000:g} km",
            )


def decode_unit_state(
    data: bytes | bytearray | memoryview | None, bounds: Bounds | None = None, origin: Origin | None = None
) -> UnitState:
    """A ``UnitState`` from a ``unit/{u}/state`` payload (see ``decode``)."""
    return decode(UnitState, data, bounds, origin)


def decode_goal(
    data: bytes | bytearray | memoryview | None, bounds: Bounds | None = None, origin: Origin | None = None
) -> Goal:
    """A ``Goal`` from a ``unit/{u}/goal`` PUT payload (see ``decode``)."""
    return decode(Goal, data, bounds, origin)


def decode_threat(
    data: bytes | bytearray | memoryview | None, bounds: Bounds | None = None, origin: Origin | None = None
) -> ThreatUpdate:
    """A ``ThreatUpdate`` from a ``threat/{t}`` PUT payload (see ``decode``)."""
    return decode(ThreatUpdate, data, bounds, origin)


def decode_zone(
    data: bytes | bytearray | memoryview | None, bounds: Bounds | None = None, origin: Origin | None = None
) -> ZoneUpdate:
    """A ``ZoneUpdate`` from a ``zone/{z}`` PUT payload (see ``decode``).

    A zone may reach past the mission bounds (a minefield's edge need not
    stop where the mission's does): ``bounds`` is not checked against it.
    """
    del bounds
    return decode(ZoneUpdate, data, None, origin)


def decode_team(
    data: bytes | bytearray | memoryview | None, bounds: Bounds | None = None, origin: Origin | None = None
) -> TeamUpdate:
    """A ``TeamUpdate`` from a ``team/{t}`` PUT payload (see ``decode``): its goal's places within ``bounds``."""
    return decode(TeamUpdate, data, bounds, origin)


def decode_preview_request(
    data: bytes | bytearray | memoryview | None, bounds: Bounds | None = None, origin: Origin | None = None
) -> PreviewRequest:
    """A ``PreviewRequest`` from a preview query body; no body means the live preview."""
    if data is None or len(data) == 0:
        return PreviewRequest()
    return decode(PreviewRequest, data, bounds, origin)


def decode_direction(data: bytes | bytearray | memoryview | None) -> Direction:
    """A ``Direction`` (for units and clients)."""
    return decode(Direction, data)


def decode_planner_status(data: bytes | bytearray | memoryview | None) -> PlannerStatus:
    """A ``PlannerStatus`` status-query reply."""
    return decode(PlannerStatus, data)


def decode_mission(data: bytes | bytearray | memoryview | None) -> Mission:
    """A ``Mission`` another planner published."""
    return decode(Mission, data)


def decode_world_snapshot(data: bytes | bytearray | memoryview | None) -> WorldSnapshot:
    """A ``WorldSnapshot`` world-query reply."""
    return decode(WorldSnapshot, data)


def decode_world_query(parameters: str) -> WorldQuery:
    """A world query's selector parameters (``query.parameters``: ``a=1;b=2``), validated.

    Raises:
        InputError: too long, not ``name=value``, a name repeated or unknown, or a
            bad value; the path names the parameter (``$.limit``).
    """
    if len(parameters) > MAX_WORLD_QUERY_CHARS:
        raise InputError("$", f"query parameters longer than {MAX_WORLD_QUERY_CHARS} characters")
    doc: dict[str, str] = {}
    for part in parameters.split(";"):
        if not part:
            continue
        name, eq, value = part.partition("=")
        if not eq:
            raise InputError("$", f"expected name=value, got {fit_text(part, 64)!r}")
        if name in doc:
            raise InputError(_rooted(name), "parameter given twice")
        if name not in WorldQuery.__struct_fields__:
            raise InputError(
                _rooted(name) if re.fullmatch(r"[A-Za-z_]\w{0,63}", name) else "$",
                f"unknown parameter (expected one of {', '.join(WorldQuery.__struct_fields__)})",
            )
        doc[name] = value
    try:
        return msgspec.convert(doc, WorldQuery, strict=False)
    except msgspec.ValidationError as exc:
        raise _wire_error(exc) from exc


def decode_error_reply(data: bytes | bytearray | memoryview | None) -> ErrorReply:
    """An ``ErrorReply`` from a ``reply_err`` body."""
    return decode(ErrorReply, data)


def decode_event(
    data: bytes | bytearray | memoryview | None,
) -> Event:
    """One planner event, by its ``kind`` tag (an unknown kind is an ``InputError`` at ``$.kind``)."""
    try:
        return decode(AnyEvent, data)  # type: ignore[arg-type]
    except InputError as exc:
        if exc.path == "$.kind" and exc.reason.startswith("invalid value"):
            raise InputError(exc.path, f"{exc.reason} (expected one of: {', '.join(EVENT_KINDS)})") from exc
        raise
