"""The world queryable in pages: answering one page, and a joining planner fetching every page.

A page itself is built by ``snapshot.page`` (pure, the world's); this module is its I/O.

A ``WorldSnapshot`` lists at most ``MAX_SNAPSHOT_ITEMS`` zones, threats, writes (the write kinds
listed by kind: teams, and any kind added since) and units each (in that order: a zone matters
most to a joining planner) and stops
short of ``SNAPSHOT_PAGE_BYTES`` of JSON, so every reply decodes; its
``next_zone``, ``next_threat``, ``next_write`` and ``next_unit`` say where the next page
starts, and the query's parameters (``WorldQuery``:
``?zones_from=ID;threats_from=ID;writes_from=KIND.ID;units_from=ID``) ask for it.  Ids are
cursors, not offsets, so an item added or removed between two pages shifts
nothing: each id present throughout is listed exactly once.  A zone may be
large (up to 4,096 vertices: 90 to 165 KB of JSON), so a world of many zones
takes several pages.

A planner joining a mission (``fetch_world``) asks every planner once, then
pages through the one holding the most, falling back to another from the same
cursor if it stops answering: every planner takes every goal, threat and zone, so
one peer's pages are the whole world.  The fetch is bounded by a page count
and a deadline, and says whether it got everything.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import msgspec

from pfp_service.errors import InputError
from pfp_service.wire import (
    ErrorReply,
    WorldQuery,
    WorldSnapshot,
    decode_world_query,
    decode_world_snapshot,
    encode,
    keys,
)
from pfp_service.world.events import Input
from pfp_service.world.kinds import inputs_from_snapshot

if TYPE_CHECKING:
    from pfp_service.world.world import World

__all__ = [
    "JOIN_DEADLINE_S",
    "JOIN_MAX_PAGES",
    "Joined",
    "answer_world",
    "fetch_world",
    "whole_world",
]

JOIN_MAX_PAGES = 1024  # 100,000 units (max_units) with missions are about 350 pages
JOIN_DEADLINE_S = 30.0
JOIN_PAGE_TIMEOUT_S = 2.0

# ask(selector, timeout_s) -> the payloads of the replies that came (``ok`` ones only)
Ask = Callable[[str, float], list[bytes]]


def answer_world(query: Any, world: World, now: float, mission: str, planner: str) -> None:
    """Reply to one world query with the page its parameters ask for, or a structured error.

    Args:
        query: the ``zenoh.Query`` (``parameters``, ``reply``, ``reply_err``).
        world: the planner's world (only its ``snapshot`` is read).
        now: the loop's clock.
        mission, planner: name the reply's key.
    """
    from pfp_service.wire.encoding import zenoh_encoding

    try:
        q = decode_world_query(str(query.parameters))
    except InputError as err:
        query.reply_err(encode(ErrorReply.of(err)), encoding=zenoh_encoding())
        return
    page = world.snapshot(
        now,
        q.units_limit,
        q.units_from,
        q.threats_from,
        threats_limit=q.threats_limit,
        zones_from=q.zones_from,
        zones_limit=q.zones_limit,
        writes_from=q.writes_from,
        writes_limit=q.writes_limit,
    )
    query.reply(keys.world(mission, planner), encode(page), encoding=zenoh_encoding())


@dataclass
class Joined:
    """What a joining planner learnt: the inputs to apply, and how the fetch went."""

    inputs: list[Input] = field(default_factory=list)
    peers: int = 0  # planners that answered the first ask
    pages: int = 0
    complete: bool = True  # every page of the peer paged through came (or there was no peer)
    units: int = 0  # units and threats listed, over every page
    threats: int = 0
    zones: int = 0
    writes: int = 0  # the write kinds listed by kind (teams, ...)

    def fields(self) -> dict[str, Any]:
        return {
            "peers": self.peers,
            "pages": self.pages,
            "complete": self.complete,
            "units": self.units,
            "threats": self.threats,
            "zones": self.zones,
            "writes": self.writes,
            "inputs": len(self.inputs),
        }


def _decode(payloads: list[bytes], me: str) -> list[WorldSnapshot]:
    out = []
    for p in payloads:
        try:
            snap = decode_world_snapshot(p)
        except InputError:
            continue
        if snap.planner != me:
            out.append(snap)
    return out


@dataclass(frozen=True)
class _Cursors:
    """Where each list of a planner's world goes on (``None``: that list is complete)."""

    units: str | None = None
    threats: str | None = None
    zones: str | None = None
    writes: str | None = None

    @classmethod
    def after(cls, page: WorldSnapshot) -> _Cursors:
        return cls(page.next_unit, page.next_threat, page.next_zone, page.next_write)

    @property
    def done(self) -> bool:
        return self.units is None and self.threats is None and self.zones is None and self.writes is None


def _next_page(ask: Ask, mission: str, planner: str, at: _Cursors, timeout_s: float) -> WorldSnapshot | None:
    """The page of ``planner``'s world from these cursors (a list whose cursor is ``None`` left out)."""
    full = WorldQuery()
    q = WorldQuery(
        units_from=at.units,
        threats_from=at.threats,
        zones_from=at.zones,
        units_limit=full.units_limit if at.units is not None else 0,
        threats_limit=full.threats_limit if at.threats is not None else 0,
        zones_limit=full.zones_limit if at.zones is not None else 0,
        writes_from=at.writes,
        writes_limit=full.writes_limit if at.writes is not None else 0,
    )
    sel = f"{keys.world(mission, planner)}?{q.selector_parameters()}"
    pages = [p for p in _decode(ask(sel, timeout_s), "") if p.planner == planner]
    return pages[0] if pages else None


def whole_world(
    ask: Ask,
    mission: str,
    first: WorldSnapshot,
    clock: Callable[[], float] = time.monotonic,
    deadline_s: float = JOIN_DEADLINE_S,
    max_pages: int = JOIN_MAX_PAGES,
    page_timeout_s: float = JOIN_PAGE_TIMEOUT_S,
) -> tuple[WorldSnapshot, bool]:
    """One planner's whole world: ``first`` and every page after it, merged (for ``pfp status``).

    Returns:
        The merged snapshot (its lists may be longer than one page's) with the
        cursors of where it stopped, and whether it is complete; a bound or the
        planner's silence cuts it short.
    """
    end = clock() + deadline_s
    units, threats, zones, writes = (
        list(first.units),
        list(first.threats),
        list(first.zones),
        list(first.writes),
    )
    at = _Cursors.after(first)
    pages = 1
    while not at.done:
        if pages >= max_pages or clock() >= end:
            break
        page = _next_page(ask, mission, first.planner, at, page_timeout_s)
        if page is None:
            break
        pages += 1
        units += page.units
        threats += page.threats
        zones += page.zones
        writes += page.writes
        at = _Cursors.after(page)
    merged = msgspec.structs.replace(
        first,
        units=units,
        threats=threats,
        zones=zones,
        writes=writes,
        next_unit=at.units,
        next_threat=at.threats,
        next_zone=at.zones,
        next_write=at.writes,
    )
    return merged, at.done


def fetch_world(
    ask: Ask,
    mission: str,
    me: str,
    clock: Callable[[], float] = time.monotonic,
    deadline_s: float = JOIN_DEADLINE_S,
    max_pages: int = JOIN_MAX_PAGES,
    page_timeout_s: float = JOIN_PAGE_TIMEOUT_S,
) -> Joined:
    """Every page of the world the mission's other planners hold, as inputs.

    Args:
        ask: sends a query and returns the ``ok`` reply payloads.
        mission: the mission.
        me: this planner's id (its own reply, if any, is skipped).
        clock, deadline_s: the fetch stops after ``deadline_s`` seconds ...
        max_pages: ... or this many pages, first ones included.
        page_timeout_s: each query's own timeout.

    Returns:
        The inputs, in page order, and the figures; ``complete`` false when a
        bound or every peer's silence cut it short.
    """
    end = clock() + deadline_s
    got = Joined()
    first = _decode(ask(keys.worlds(mission), page_timeout_s), me)
    got.peers = len(first)

    def take(page: WorldSnapshot) -> None:
        got.inputs.extend(inputs_from_snapshot(page, me))
        got.pages += 1
        got.units += len(page.units)
        got.threats += len(page.threats)
        got.zones += len(page.zones)
        got.writes += len(page.writes)

    for page in first:
        take(page)
    if not first:
        return got
    # the fullest peer first; the others, in turn, if it stops answering
    peers = sorted(
        first, key=lambda p: (-(p.units_total + p.threats_total + p.zones_total + p.writes_total), p.planner)
    )
    at = _Cursors.after(peers[0])
    for peer in peers:
        while not at.done:
            if got.pages >= max_pages or clock() >= end:
                got.complete = False
                return got
            more = _next_page(ask, mission, peer.planner, at, page_timeout_s)
            if more is None:
                break  # this peer is gone or will not answer: the next one, from the same cursor
            take(more)
            at = _Cursors.after(more)  # a list left out has none
        else:
            return got
    got.complete = False
    return got
