"""The planner's terrain, seen from the node: loaded before anything starts, named in the status.

``placed`` loads the DEM of ``ServeConfig.terrain`` (``terrain.live.load``,
once per process) and gives the configuration its origin: the DEM's centre
when none was given, so every position on the wire, the status and the
zones' file share the plane the world plans on.  ``terrain_info`` is the
status's ``TerrainInfo`` (a peer over another DEM is the world's conflict:
``world.cluster.terrain_conflict``).
"""

from __future__ import annotations

import msgspec

from pfp_service.node.config import ServeConfig
from pfp_service.wire.messages import TerrainInfo

__all__ = ["placed", "terrain_info"]


def placed(cfg: ServeConfig) -> ServeConfig:
    """``cfg`` with its terrain loaded and its origin the terrain's.

    Raises:
        InputError: the DEM cannot be read, placed, or does not cover the bounds (one line, naming the file).
    """
    if cfg.terrain is None:
        return cfg
    from pfp_service.terrain.live import load

    ground = load(cfg.terrain, cfg.origin, cfg.bounds_tuple(), cfg.terrain_unit)
    return msgspec.structs.replace(cfg, origin=ground.origin)


def terrain_info(cfg: ServeConfig) -> TerrainInfo | None:
    """What ``PlannerStatus.terrain`` says of ``cfg``'s terrain (loaded already: ``placed``)."""
    ground = cfg.world_settings().terrain
    if ground is None:
        return None
    a = ground.about  # type: ignore[attr-defined]
    return TerrainInfo(
        file=a.file[:200],
        sha256=a.sha256,
        south=a.south,
        west=a.west,
        north=a.north,
        east=a.east,
        resolution_m=a.resolution_m,
        unit=a.unit,
        origin_centred=a.centred,
    )
