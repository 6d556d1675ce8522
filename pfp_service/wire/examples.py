"""An example instance of every wire message, by name: what ``schemas/`` shows beside each schema.

``schema.render()`` writes them into the published contract, and the tests decode each one
back, so an example is always a valid message.  Apart from ``schema`` because they are data,
not the rules that turn Structs into schemas.  The preview reply's example is the core's
``PlanResult``, which the wire cannot name: ``world.translate.supplied()`` gives it.
"""

from __future__ import annotations

from typing import Any

from pfp_service.wire import keys
from pfp_service.wire import messages as m

__all__ = ["examples"]


def examples() -> dict[str, list[tuple[str, Any]]]:
    """Example instances by message name, as ``(example name, struct)`` pairs (but the preview reply's)."""
    hit = m.WhatIfThreat(
        id="ambush",
        position=(5.0, 6.0),
        facing_deg=225.0,
        sigma_range=1.5,
        sigma_lateral=0.8,
        skew=2.0,
        weight=1.0,
    )
    return {
        "unit_state": [
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
            )
        ],
        "goal": [("goal", m.Goal(position=(10.0, 10.0), tolerance=0.1))],
        "threat": [
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
                m.ThreatUpdate(position=(40.0, 25.0), shape="area", params={"radius_m": 6.0}, ttl_s=600.0),
            ),
        ],
        "zone": [
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
        ],
        "team": [
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
        ],
        "direction": [
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
        ],
        "preview_request": [
            (
                "preview_request",
                m.PreviewRequest(start=(0.0, 0.0), goal=(10.0, 10.0), threats=[hit], max_iter=2000),
            )
        ],
        "error_reply": [("error_reply", m.ErrorReply(error="must be > 0", field="$.threats[0].sigma_range"))],
        "planner_status": [
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
        ],
        "mission": [
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
        ],
        "world_snapshot": [
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
                                polygon=[[(20.0, 0.0), (30.0, 0.0), (30.0, 8.0), (20.0, 8.0), (20.0, 0.0)]]
                            ),
                        )
                    ],
                    units_total=1,
                    threats_total=1,
                    zones_total=2,
                    next_zone="pond",
                ),
            )
        ],
        "event": [
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
            ("event.arrived", m.ArrivedEvent(unit="ugv-1", position=(9.97, 10.02), distance_to_goal=0.036)),
            ("event.stale", m.StaleEvent(unit="ugv-3", position=(120.0, 40.5), reason="silent for 10 s")),
            ("event.forgotten", m.ForgottenEvent(unit="ugv-3", stale_s=600.0)),
            ("event.restored", m.RestoredEvent(threats=20, goals=50, missions=48, expired=1, zones=3)),
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
        ],
    }
