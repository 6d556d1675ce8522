"""One page of the world snapshot, built from the world's records: pure, no I/O.

The world answers ``snapshot(...)`` with it; ``worldpages`` is the I/O around it (the
queryable's reply, a joining planner fetching every page).  Kept apart so the sans-I/O
world never imports the clock or the Zenoh side of paging, and the two never import each
other (issue 31: no circles).  The page's bounds and cursors are described in ``worldpages``.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import TypeVar

import msgspec

from pfp_service.wire import ThreatSummary, UnitKind, UnitSummary, WorldSnapshot
from pfp_service.wire.messages import (
    MAX_SNAPSHOT_ITEMS,
    SNAPSHOT_PAGE_BYTES,
    TeamSummary,
    WriteSummary,
    ZoneSummary,
)
from pfp_service.world.events import mission_of
from pfp_service.world.kinds import Held
from pfp_service.world.world_records import Records, UnitRecord

__all__ = ["page"]

R = TypeVar("R")  # a record of the world's (unit, threat, zone)
S = TypeVar("S", bound=msgspec.Struct)  # its summary on the page


def page(
    records: Records,
    now: float,
    mission: str,
    planner: str,
    limit: int = MAX_SNAPSHOT_ITEMS,
    units_from: str | None = None,
    threats_from: str | None = None,
    max_bytes: int | None = None,
    threats_limit: int | None = None,
    zones_from: str | None = None,
    zones_limit: int | None = None,
    teams: Sequence[TeamSummary] = (),
    held: Held | None = None,
    writes_from: str | None = None,
    writes_limit: int | None = None,
) -> WorldSnapshot:
    """One page of what a planner holds, for the world queryable: zones, threats, writes, then units, sorted by id.

    Args:
        records: the world's records (read only).
        now: the clock, for TTLs left and time since last seen.
        mission, planner: name the page.
        limit: at most this many units, and this many threats and zones
            unless ``threats_limit`` and ``zones_limit`` say otherwise.
        units_from, threats_from, zones_from: the first ids listed (a former
            page's ``next_unit``, ``next_threat`` and ``next_zone``); ``None``:
            from the first.
        max_bytes: the page's items stop short of this much JSON
            (default ``SNAPSHOT_PAGE_BYTES``, so a reply always decodes).
        teams: the teams in force, listed first on the first page (as many as fit), on no other.
        held: the records of the write kinds listed by kind (``world.kinds.Kind.held``), by
            ``kind.id``: listed after the threats, from ``writes_from``, at most ``writes_limit``.

    Returns:
        The page; its ``next_unit``, ``next_threat`` and ``next_zone`` say where the next
        one starts (``None``: that list is complete, or was not asked for
        with a limit of 0).  A page with room for nothing still lists one
        item, so paging always ends.
    """
    room = SNAPSHOT_PAGE_BYTES if max_bytes is None else max_bytes

    def fits(item: msgspec.Struct) -> bool:
        nonlocal room
        size = len(msgspec.json.encode(item)) + 1  # and its comma
        if size > room and (units or threats or zones or writes):
            return False
        room -= size
        return True

    units: list[UnitSummary] = []
    threats: list[ThreatSummary] = []
    zones: list[ZoneSummary] = []
    writes: list[WriteSummary] = []

    def listing(
        records_of: Mapping[str, R],
        start: str | None,
        most: int,
        summary: Callable[[str, R], S],
        out: list[S],
    ) -> str | None:
        """Fill ``out`` from ``start`` on, in id order, while ``most`` and the page's room allow; the next id."""
        ids = sorted(records_of)
        i = bisect.bisect_left(ids, start) if start is not None else 0
        while i < len(ids) and len(out) < most:
            item = summary(ids[i], records_of[ids[i]])
            if not fits(item):
                break
            out.append(item)
            i += 1
        return ids[i] if i < len(ids) and most else None

    def ttl(expires_at: float | None) -> float | None:
        return None if expires_at is None else max(expires_at - now, 0.0)

    def unit_summary(uid: str, r: UnitRecord) -> UnitSummary:
        return UnitSummary(
            id=uid,
            kind=UnitKind(r.kind) if r.kind is not None else None,
            status=r.last_status,
            position=r.position,
            goal=r.goal.position if r.goal is not None else None,
            last_seen_s=max(now - r.last_seen, 0.0) if math.isfinite(r.last_seen) else None,
            distance_to_goal=r.last_distance,
            stale=r.stale,
            deliberating=r.job is not None,
            reason=r.last_reason[:1024],
            mission=mission_of(r.shared, planner if r.owned else None),
            phase=r.phase,
        )

    listed_teams: list[TeamSummary] = []
    if units_from is None and threats_from is None and zones_from is None and writes_from is None:
        listed_teams = list(itertools.takewhile(fits, teams[:MAX_SNAPSHOT_ITEMS]))
    next_zone = listing(
        records.zones,
        zones_from,
        limit if zones_limit is None else zones_limit,
        lambda zid, z: ZoneSummary(id=zid, zone=z.update, ttl_s=ttl(z.expires_at)),
        zones,
    )
    next_threat = listing(
        records.threats,
        threats_from,
        limit if threats_limit is None else threats_limit,
        lambda tid, t: ThreatSummary(id=tid, threat=t.update, ttl_s=ttl(t.expires_at)),
        threats,
    )
    next_write = listing(
        held or {},
        writes_from,
        limit if writes_limit is None else writes_limit,
        lambda _key, h: WriteSummary(kind=h[0], id=h[1], body=msgspec.to_builtins(h[2]), ttl_s=ttl(h[3])),
        writes,
    )
    next_unit = listing(records.units, units_from, limit, unit_summary, units)
    return WorldSnapshot(
        teams=listed_teams,
        teams_total=len(teams),
        planner=planner,
        mission=mission,
        units=units,
        threats=threats,
        zones=zones,
        zones_total=len(records.zones),
        units_total=len(records.units),
        threats_total=len(records.threats),
        next_unit=next_unit,
        next_threat=next_threat,
        next_zone=next_zone,
        writes=writes,
        writes_total=len(held or {}),
        next_write=next_write,
    )
