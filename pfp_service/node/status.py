"""The planner's answer to a status query (``PlannerStatus``): the world's counts, the loop's figures.

Built from values the node hands over, so the reply's fields are filled in one place.
"""

from __future__ import annotations

from collections.abc import Mapping

from pfp_service import __version__
from pfp_service.node.config import ServeConfig
from pfp_service.node.loopstats import Latency
from pfp_service.node.terrain import terrain_info
from pfp_service.wire import PlannerStatus

__all__ = ["planner_status"]


def planner_status(
    cfg: ServeConfig,
    counts: Mapping[str, int],
    latency: Latency,
    counters: Mapping[str, int],
    uptime_s: float,
    session: str,
    twins: tuple[str, ...],
) -> PlannerStatus:
    """The status of the planner ``cfg`` names, with the world's ``counts`` and the node's ``counters``."""
    p50, p99 = latency.quantiles_ms()
    c = counts
    return PlannerStatus(
        planner=cfg.planner_id,
        mission=cfg.mission,
        version=__version__,
        uptime_s=uptime_s,
        units=c["units"],
        units_stale=c["units_stale"],
        threats=c["threats"],
        zones=c["zones"],
        msgs_in=counters["msgs_in"],
        msgs_out=counters["msgs_out"],
        rejected=c["rejected"],
        latency_p50_ms=p50,
        latency_p99_ms=p99,
        deliberating=c["deliberating"],
        units_owned=c["units_owned"],
        overload=c["overload"],
        pushes=c["pushes"],
        pushes_resent=c["pushes_resent"],
        session=session,
        origin=cfg.origin,
        faults=c["faults"],
        twins=twins,
        terrain=terrain_info(cfg),
    )
