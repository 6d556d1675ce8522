"""The wire contract's messages: each one's name, type, key, who sends it how, and example instances.

One ``MessageSpec`` in ``MESSAGES`` per message, its examples beside it, so a new message is one
entry here (``schema.render()`` turns them into ``schemas/``; the tests decode every example back,
so an example is always a valid message).  The preview reply's type and example are the core's
``PlanResult``, which the wire cannot name: ``world.translate.supplied()`` gives them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pfp_service.wire import keys
from pfp_service.wire import messages as m
from pfp_service.wire.keys import KeyKind

__all__ = ["LIVELINESS", "MESSAGES", "MessageSpec", "examples"]

_HIT = m.WhatIfThreat(
    id="ambush",
    position=(5.0, 6.0),
    facing_deg=225.0,
    sigma_range=1.5,
    sigma_lateral=0.8,
    skew=2.0,
    weight=1.0,
)


@dataclass(frozen=True)
class MessageSpec:
    """One message of the contract: its name, type, key, who sends it how, and its examples."""

    name: str
    type: Any
    key: KeyKind | None
    op: str
    sender: str
    receiver: str
    note: str = ""
    examples: tuple[tuple[str, Any], ...] = ()  # (example name, instance): schemas/examples/NAME.json


MESSAGES: tuple[MessageSpec, ...] = (
    MessageSpec(
        "unit_state",
        m.UnitState,
        KeyKind.UNIT_STATE,
        "put",
        "unit",
        "planner",
        examples=tuple(
            [
                (
                    "unit_state",
                    m.UnitState(
                        position=(1.5, 2.25),
                        t=1767225600.5,
                        seq=42,
                        kind=m.UnitKind.UNMANNED,
                        speed_mps=1.2,
                        heading_deg=45.0,
                    ),
                ),
                (
                    "unit_state.mobility",
                    m.UnitState(
                        position=(1.5, 2.25), seq=43, mobility=m.GoalMobility(kind="tracked", height_m=3.5)
                    ),
                ),
            ]
        ),
    ),
    MessageSpec(
        "goal",
        m.Goal,
        KeyKind.UNIT_GOAL,
        "put",
        "any",
        "planner",
        "a DELETE on the key cancels the goal",
        examples=tuple(
            [
                ("goal", m.Goal(position=(10.0, 10.0), tolerance=0.1)),
                (
                    "goal.mobility",
                    m.Goal(
                        position=(10.0, 10.0),
                        mobility=m.GoalMobility(kind="wheeled", max_slope_deg=20.0, speed_mps=6.0),
                    ),
                ),
            ]
        ),
    ),
    MessageSpec(
        "threat",
        m.ThreatUpdate,
        KeyKind.THREAT,
        "put",
        "any",
        "planner",
        "a DELETE on the key removes the threat",
        examples=tuple(
            [
                (
                    "threat",
                    m.ThreatUpdate(
                        position=(4.0, 5.0),
                        facing_deg=180.0,
                        sigma_range=2.0,
                        sigma_lateral=1.0,
                        skew=3.0,
                        weight=1.0,
                        ttl_s=30.0,
                    ),
                ),
                (
                    "threat.area",
                    m.ThreatUpdate(
                        position=(40.0, 25.0), shape="area", params={"radius_m": 6.0}, ttl_s=600.0
                    ),
                ),
            ]
        ),
    ),
    MessageSpec(
        "zone",
        m.ZoneUpdate,
        KeyKind.ZONE,
        "put",
        "any",
        "planner",
        "a keep-out zone no path enters; a DELETE on the key removes it",
        examples=tuple(
            [
                (
                    "zone",
                    m.ZoneUpdate(
                        polygon=[
                            [(100.0, 40.0), (160.0, 40.0), (160.0, 90.0), (100.0, 90.0), (100.0, 40.0)],
                            [(120.0, 55.0), (135.0, 55.0), (135.0, 70.0), (120.0, 55.0)],
                        ],
                        ttl_s=3600.0,
                    ),
                ),
                ("zone.circle", m.ZoneUpdate(circle=m.ZoneCircle(centre=(-40.0, 75.0), radius_m=25.0))),
            ]
        ),
    ),
    MessageSpec(
        "team",
        m.TeamUpdate,
        KeyKind.TEAM,
        "put",
        "any",
        "planner",
        "a team and its roles (lead, follow, controller and robots); a DELETE on the key dissolves it",
        examples=tuple(
            [
                (
                    "team",
                    m.TeamUpdate(
                        separation_m=20.0,
                        lead="r1",
                        follow=["m1", "m2"],
                        standoff_m=300.0,
                        corridor_m=30.0,
                        controller="m1",
                        robots=["r1", "r2"],
                        radio_range_m=1500.0,
                    ),
                )
            ]
        ),
    ),
    MessageSpec(
        "direction",
        m.Direction,
        KeyKind.UNIT_DIRECTION,
        "put",
        "planner",
        "unit",
        examples=tuple(
            [
                (
                    "direction",
                    m.Direction(
                        unit="ugv-1",
                        seq=42,
                        status=m.DirectionStatus.EN_ROUTE,
                        vector=(0.6, 0.8),
                        heading_deg=36.87,
                        distance_to_goal=10.2,
                        threat_level=0.031,
                        lookahead=[(1.56, 2.33), (1.62, 2.41)],
                        reach_m=0.1,
                    ),
                )
            ]
        ),
    ),
    MessageSpec(
        "mission",
        m.Mission,
        KeyKind.UNIT_MISSION,
        "put",
        "planner",
        "planner",
        "a unit's x0 and resolved parameters, so another planner can take it over",
        examples=tuple(
            [
                (
                    "mission",
                    m.Mission(
                        goal=m.Goal(position=(100.0, 50.0)),
                        origin=(0.0, 0.0),
                        params=m.MissionParams(
                            delta=1.2,
                            step=0.75,
                            max_iter=1200,
                            tolerance=0.5625,
                            intensity="peak",
                            escape="auto",
                            trap_window=20,
                            progress_window=200,
                        ),
                        planner="planner-1",
                    ),
                )
            ]
        ),
    ),
    MessageSpec(
        "preview_request",
        m.PreviewRequest,
        KeyKind.PREVIEW,
        "get payload",
        "any",
        "planner",
        "optional; no payload previews the unit's live state to its live goal",
        examples=tuple(
            [
                (
                    "preview_request",
                    m.PreviewRequest(start=(0.0, 0.0), goal=(10.0, 10.0), threats=[_HIT], max_iter=2000),
                )
            ]
        ),
    ),
    MessageSpec(
        "preview_reply",
        None,  # the core's PlanResult, which the wire cannot name: supplied to render()
        KeyKind.PREVIEW,
        "reply",
        "planner",
        "any",
        "the same object as `pfp plan --json`; with `geojson: true` in the request, an RFC 7946 "
        "FeatureCollection (path, threats, zones) in WGS-84",
    ),
    MessageSpec(
        "team_preview_request",
        m.TeamPreviewRequest,
        KeyKind.TEAM_PREVIEW,
        "get payload",
        "any",
        "planner",
        "optional; no payload replays the team from its members' live states for up to 600 s",
        examples=(
            ("team_preview_request", m.TeamPreviewRequest(horizon_s=300.0, dt_s=0.5, speeds={"r1": 3.0})),
        ),
    ),
    MessageSpec(
        "team_preview",
        m.TeamPreview,
        KeyKind.TEAM_PREVIEW,
        "reply",
        "planner",
        "any",
        "every member's track over time as the live world would drive it, and the team's ETA",
        examples=(
            (
                "team_preview",
                m.TeamPreview(
                    team="alpha",
                    eta_s=95.5,
                    members=[
                        m.MemberTrack(
                            unit="m1",
                            speed_mps=2.0,
                            points=[(0.0, 59.0, 0.0), (0.5, 60.0, 0.0), (95.5, 239.29, 0.06)],
                            statuses=[
                                m.StatusChange(t_s=0.0, status=m.DirectionStatus.EN_ROUTE),
                                m.StatusChange(
                                    t_s=16.5,
                                    status=m.DirectionStatus.EN_ROUTE,
                                    reason="team alpha: kept to the corridor r1 cleared",
                                ),
                                m.StatusChange(t_s=95.5, status=m.DirectionStatus.ARRIVED),
                            ],
                            arrived_s=95.5,
                        )
                    ],
                    simulated_s=95.5,
                    outsiders=["a1"],
                ),
            ),
        ),
    ),
    MessageSpec(
        "error_reply",
        m.ErrorReply,
        None,
        "reply_err",
        "planner",
        "any",
        "answer to a bad preview, status or world query",
        examples=tuple(
            [("error_reply", m.ErrorReply(error="must be > 0", field="$.threats[0].sigma_range"))]
        ),
    ),
    MessageSpec(
        "planner_status",
        m.PlannerStatus,
        KeyKind.PLANNER_STATUS,
        "reply",
        "planner",
        "any",
        examples=tuple(
            [
                (
                    "planner_status",
                    m.PlannerStatus(
                        planner="planner-1",
                        mission="default",
                        version="0.1.0",
                        uptime_s=3600.0,
                        units=12,
                        units_stale=1,
                        threats=5,
                        zones=2,
                        msgs_in=43200,
                        msgs_out=43190,
                        rejected=3,
                        latency_p50_ms=0.21,
                        latency_p99_ms=0.9,
                    ),
                )
            ]
        ),
    ),
    MessageSpec(
        "world_snapshot",
        m.WorldSnapshot,
        KeyKind.WORLD,
        "reply",
        "planner",
        "any",
        "keep-out zones, threats, writes (teams, and kinds added since) and units the planner holds, "
        "a page at a time: `next_zone`/`next_threat`/`next_write`/`next_unit` say where the next page "
        "starts, asked with `?zones_from=ID;threats_from=ID;writes_from=KIND.ID;units_from=ID` (and "
        "`zones_limit`, `threats_limit`, `writes_limit`, `units_limit`: 0 to 1000, 0 leaves a list "
        "out); a bad parameter gets an error_reply; `pfp status` asks every planner",
        examples=tuple(
            [
                (
                    "world_snapshot",
                    m.WorldSnapshot(
                        planner="planner-1",
                        mission="default",
                        units=[
                            m.UnitSummary(
                                id="ugv-1",
                                kind=m.UnitKind.UNMANNED,
                                status=m.DirectionStatus.EN_ROUTE,
                                position=(4.6, 4.9),
                                goal=(10.0, 10.0),
                                last_seen_s=0.4,
                                distance_to_goal=7.4,
                                phase=m.UnitPhase.GUIDED,
                            )
                        ],
                        threats=[
                            m.ThreatSummary(
                                id="ambush",
                                threat=m.ThreatUpdate(
                                    position=(5.0, 5.0),
                                    facing_deg=225.0,
                                    sigma_range=1.0,
                                    sigma_lateral=0.7,
                                    skew=2.0,
                                ),
                                ttl_s=25.0,
                            )
                        ],
                        zones=[
                            m.ZoneSummary(
                                id="minefield",
                                zone=m.ZoneUpdate(
                                    polygon=[
                                        [(20.0, 0.0), (30.0, 0.0), (30.0, 8.0), (20.0, 8.0), (20.0, 0.0)]
                                    ]
                                ),
                            )
                        ],
                        writes=[
                            m.WriteSummary(
                                kind="team", id="alpha", body={"lead": "r1", "follow": ["m1", "m2"]}
                            )
                        ],
                        writes_total=1,
                        units_total=1,
                        threats_total=1,
                        zones_total=2,
                        next_zone="pond",
                    ),
                )
            ]
        ),
    ),
    MessageSpec(
        "event",
        m.AnyEvent,
        KeyKind.EVENT,
        "put",
        "planner",
        "any",
        "`kind` repeats the key's last chunk",
        examples=tuple(
            [
                (
                    "event.rejected",
                    m.RejectedEvent(
                        key=keys.unit_state(keys.DEFAULT_MISSION, "ugv-1"),
                        field="$.position[1]",
                        reason="expected a finite number within ±1e+09",
                        planner="planner-1",
                        t=1767225600.5,
                    ),
                ),
                (
                    "event.replan",
                    m.ReplanEvent(
                        units=["ugv-1", "tank-2"],
                        reason="threat ambush put",
                        changes=[m.ThreatChange(threat="ambush", change="put", position=(310.0, 220.0))],
                        planner="planner-1",
                    ),
                ),
                (
                    "event.trapped",
                    m.TrappedEvent(unit="ugv-1", position=(4.6, 4.9), reason="no progress in 200 steps"),
                ),
                (
                    "event.arrived",
                    m.ArrivedEvent(unit="ugv-1", position=(9.97, 10.02), distance_to_goal=0.036),
                ),
                ("event.stale", m.StaleEvent(unit="ugv-3", position=(120.0, 40.5), reason="silent for 10 s")),
                ("event.forgotten", m.ForgottenEvent(unit="ugv-3", stale_s=600.0)),
                (
                    "event.restored",
                    m.RestoredEvent.counted(
                        {"goal": 50, "threat": 20, "zone": 3, "team": 1}, missions=48, expired=1
                    ),
                ),
                (
                    "event.conflict",
                    m.ConflictEvent(other="planner-2", reason="a second planner on mission default"),
                ),
                (
                    "event.deadlock",
                    m.DeadlockEvent(
                        unit="ugv-2",
                        other="ugv-1",
                        position=(310.0, 42.0),
                        held_s=10.2,
                        backoff_s=10.0,
                        reason="ugv-2 held 10 s for ugv-1, which did not draw away: ugv-2 backs off for 10 s",
                    ),
                ),
            ]
        ),
    ),
)

LIVELINESS: tuple[KeyKind, ...] = (KeyKind.ALIVE_UNIT, KeyKind.ALIVE_PLANNER)


def examples() -> dict[str, list[tuple[str, Any]]]:
    """Example instances by message name, as ``(example name, struct)`` pairs (but the preview reply's)."""
    return {spec.name: list(spec.examples) for spec in MESSAGES if spec.type is not None}
