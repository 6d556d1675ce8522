"""The public API of ``pfp_service.wire``, pinned: adding or dropping a name is a deliberate edit here."""

from __future__ import annotations

import types

import pytest

import pfp_service.wire as wire
from pfp_service.wire import messages

pytestmark = pytest.mark.unit

EXPECTED = [
    "CONTENT_TYPE",
    "GOAL_CANCELLED",
    "MAX_PAYLOAD_BYTES",
    "ArrivedEvent",
    "Bounds",
    "ConflictEvent",
    "DeadlockEvent",
    "Direction",
    "DirectionStatus",
    "ErrorReply",
    "Event",
    "ForgottenEvent",
    "Goal",
    "GoalMobility",
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
    "TeamUpdate",
    "ThreatChange",
    "ThreatSummary",
    "ThreatUpdate",
    "TrappedEvent",
    "UnitKind",
    "UnitPhase",
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
    "decode_planner_status",
    "decode_preview_request",
    "decode_team",
    "decode_threat",
    "decode_unit_state",
    "decode_world_query",
    "decode_world_snapshot",
    "decode_zone",
    "encode",
    "keys",
]


def test_wire_all_is_pinned():
    assert wire.__all__ == EXPECTED


def test_every_public_member_is_exported():
    # as httpx's test_exported_members: whatever the package binds publicly is in __all__, and only that;
    # submodules other than ``keys`` are reached by their own import, not through the package.
    public = {
        name
        for name, value in vars(wire).items()
        if not name.startswith("_")
        and name not in {"annotations", "TYPE_CHECKING"}
        and (not isinstance(value, types.ModuleType) or name == "keys")
    }
    assert sorted(public) == sorted(wire.__all__)


def test_package_re_exports_the_messages_objects():
    for name in wire.__all__:
        if hasattr(messages, name):
            assert getattr(wire, name) is getattr(messages, name), name
