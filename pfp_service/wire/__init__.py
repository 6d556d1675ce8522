"""The wire contract: message Structs (``messages``), key expressions (``keys``), JSON Schemas (``schema``).

Nothing here opens a session.  ``messages`` and ``keys`` never import zenoh;
the one Zenoh-specific choice, the encoding every payload is put with, is
``zenoh_encoding()`` below, which imports zenoh only when called.
``delivery`` is how every client writes goals and threats: acknowledged
writes that reach a planner started later (its ``Deliverer`` is given an
open session).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pfp_service.wire import keys
from pfp_service.wire.messages import (
    CONTENT_TYPE,
    MAX_PAYLOAD_BYTES,
    ArrivedEvent,
    Bounds,
    ConflictEvent,
    Direction,
    DirectionStatus,
    ErrorReply,
    Event,
    ForgottenEvent,
    Goal,
    LatLon,
    Mission,
    MissionParams,
    Origin,
    PlannerStatus,
    PreviewRequest,
    Progress,
    RejectedEvent,
    ReplanEvent,
    RestoredEvent,
    RouteKind,
    StaleEvent,
    ThreatChange,
    ThreatSummary,
    ThreatUpdate,
    TrappedEvent,
    UnitKind,
    UnitState,
    UnitSummary,
    WhatIfThreat,
    WorldQuery,
    WorldSnapshot,
    check_bounds,
    decode,
    decode_direction,
    decode_error_reply,
    decode_event,
    decode_goal,
    decode_mission,
    decode_plan_result,
    decode_planner_status,
    decode_preview_request,
    decode_threat,
    decode_unit_state,
    decode_world_query,
    decode_world_snapshot,
    decode_zone,
    encode,
)

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "CONTENT_TYPE",
    "MAX_PAYLOAD_BYTES",
    "ArrivedEvent",
    "Bounds",
    "ConflictEvent",
    "Direction",
    "DirectionStatus",
    "ErrorReply",
    "Event",
    "ForgottenEvent",
    "Goal",
    "LatLon",
    "Mission",
    "MissionParams",
    "Origin",
    "PlannerStatus",
    "PreviewRequest",
    "Progress",
    "RejectedEvent",
    "ReplanEvent",
    "RestoredEvent",
    "RouteKind",
    "StaleEvent",
    "ThreatChange",
    "ThreatSummary",
    "ThreatUpdate",
    "TrappedEvent",
    "UnitKind",
    "UnitState",
    "UnitSummary",
    "WhatIfThreat",
    "WorldQuery",
    "WorldSnapshot",
    "check_bounds",
    "decode",
    "decode_direction",
    "decode_error_reply",
    "decode_event",
    "decode_goal",
    "decode_mission",
    "decode_plan_result",
    "decode_planner_status",
    "decode_preview_request",
    "decode_threat",
    "decode_unit_state",
    "decode_world_query",
    "decode_world_snapshot",
    "decode_zone",
    "encode",
    "keys",
    "zenoh_encoding",
]


def zenoh_encoding() -> zenoh.Encoding:
    """The Zenoh encoding every payload is put and replied with: ``APPLICATION_JSON``.

    Predefined encodings travel as a small integer; ``str()`` of it is ``CONTENT_TYPE``.
    """
    import zenoh

    return zenoh.Encoding.APPLICATION_JSON
