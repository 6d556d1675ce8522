"""A wave's re-directions paid in chunks: the units a change reaches, told at most ``WAVE_PER_TICK`` an ``apply``.

A threat put (or its window landed over terrain) re-judges every unit it
reaches in one ``apply`` (cheap: a version bumped, a job superseded), but
steering them all there held the loop for the whole wave: a state that
came meanwhile waited for it (the bystanders' tail, issue 32).  So a wave
larger than ``WAVE_PER_TICK`` directs its first share in the ``apply`` that
changed the world, the units nearest the change first, and owes the rest
(``Wave``): each later ``apply`` directs the next share, the states that
came meanwhile with it, until none is owed (``World.wave_pending``).  A unit
heard, re-judged again, given a new goal or gone since is answered
otherwise and dropped from the queue.

Over terrain the change is a window landing, and its first pass was the reach
test over every unit (``reach.reached``, the level of the threat's masked
field along each corridor seen by it).  That test needs only the window and
the units' corridors, so the put's ask carries the corridors as they stand
(``Corridors``) and the sight thread judges them with the window it has just
computed (``answered``: a ``Judged``, off the loop).  The landing then
re-tests only the units whose corridor changed since, or that were not
guided yet (``reached_with``), with the same test.  Pure values: no clock,
no I/O.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pfp_service.core.stepper import Stepper
from pfp_service.world import reach
from pfp_service.world.terrain import Ground, SightAsk, SightLanded, answer

if TYPE_CHECKING:
    from pfp_service.core import Threat
    from pfp_service.core.visibility import Sight, Window
    from pfp_service.world.world_records import UnitRecord

__all__ = [
    "POINTS_BUDGET_S",
    "POINTS_CHUNK",
    "WAVE_BUDGET_S",
    "WAVE_CHUNK",
    "WAVE_PER_TICK",
    "Budget",
    "Corridors",
    "Judged",
    "Wave",
    "answered",
    "corridors",
    "guided",
    "judge",
    "nearest_first",
    "reached_with",
    "split",
]

# units of a wave steered an ``apply`` (figures: docs/operations.md, "The wave first"); timed (``Budget``), at most
WAVE_PER_TICK = 64
# a timed apply's share is drawn this many units at a time while its budget lasts, one chunk at least
WAVE_CHUNK = 16
# what a timed apply may spend before it draws no more of a wave (figures: BENCHMARKS.md, "Shares by time")
WAVE_BUDGET_S = 0.003
# a wave's points (its look-aheads, and the jobs they ask) once every direction is out: no unit waits for them to
# move, so a timed apply spends less on them, in smaller chunks (BENCHMARKS.md, "Zone sets pickled once")
POINTS_BUDGET_S = 0.0015
POINTS_CHUNK = 8


def nearest_first(recs: Sequence[UnitRecord], centres: Sequence[tuple[float, float]]) -> list[UnitRecord]:
    """``recs`` (each with a position) ordered by distance to the nearest of ``centres``, nearest first (stable)."""
    if not centres or len(recs) < 2:
        return list(recs)
    pos = np.array([r.position for r in recs], dtype=float).reshape(-1, 2)
    c = np.array(centres, dtype=float).reshape(-1, 2)
    d = np.hypot(pos[:, None, 0] - c[None, :, 0], pos[:, None, 1] - c[None, :, 1]).min(axis=1)
    d = np.where(np.isfinite(d), d, np.inf)
    return [recs[i] for i in np.argsort(d, kind="stable")]


def split(
    hit: Sequence[UnitRecord],
    touched: Sequence[Threat],
    zones: Sequence[tuple[float, float, float, float]],
    dirty: Collection[str],
    limit: int,
) -> tuple[list[UnitRecord], list[UnitRecord]]:
    """The units a change reached: those to steer now (at most ``limit``, and every one heard in this batch,
    ``dirty``) and those owed, nearest the threats ``touched`` and the ``zones`` (boxes) changed first."""
    if len(hit) <= limit:
        return list(hit), []
    centres = [(float(t.xi[0]), float(t.xi[1])) for t in touched]
    centres += [((z[0] + z[2]) / 2.0, (z[1] + z[3]) / 2.0) for z in zones]
    ordered = nearest_first(hit, centres)
    now = ordered[:limit] + [r for r in ordered[limit:] if r.id in dirty]
    return now, [r for r in ordered[limit:] if r.id not in dirty]


class Budget:
    """One timed ``apply``'s time for a wave's share: spent ``WAVE_BUDGET_S`` after the apply began, on the driver's clock.

    The clock is the driver's, passed in as a value (the world never reads
    one of its own): the node's loop passes its thread's CPU clock, so a
    share is what the apply can afford after its batch's own units, not a
    count, and a state that comes during a wave waits for about one budget,
    not one share.
    """

    def __init__(self, clock: Callable[[], float]) -> None:
        self._clock = clock
        self._began = clock()
        self._until = self._began + WAVE_BUDGET_S

    def spent(self) -> bool:
        """Whether the apply's budget is gone."""
        return self._clock() >= self._until

    def points_spent(self) -> bool:
        """Whether the apply's budget for a wave's points (``POINTS_BUDGET_S``) is gone."""
        return self._clock() >= self._began + POINTS_BUDGET_S


class Wave:
    """The units of a wave still owed their direction, in the order they are to get it."""

    def __init__(self) -> None:
        # by unit: the record, its stepper, the version it was re-judged at and its report's seq then
        self._owed: dict[str, tuple[UnitRecord, Stepper, int, int | None]] = {}  # in the queue's order

    def __bool__(self) -> bool:
        return bool(self._owed)

    def __len__(self) -> int:
        return len(self._owed)

    def owe(self, recs: Sequence[UnitRecord]) -> None:
        """Owe ``recs`` (each re-judged, with a stepper) their direction, after those owed already."""
        for rec in recs:
            st = rec.stepper
            if st is not None:
                self._owed.pop(rec.id, None)
                self._owed[rec.id] = (rec, st, st.version, rec.seq)

    def ids(self) -> list[str]:
        """The units owed (a replan event names them with those told at once)."""
        return list(self._owed)

    def take(self, dirty: Collection[str], units: Mapping[str, UnitRecord], limit: int) -> list[str]:
        """The next ``limit`` units owed and still as they were re-judged; each is owed no longer.

        One ``dirty`` already (heard in this batch), heard since it was owed,
        gone, stale, or with another stepper or version since is answered
        otherwise: dropped.
        """
        got: list[str] = []
        for uid in list(self._owed):
            if len(got) >= limit:
                break
            rec, st, version, seq = self._owed.pop(uid)
            if uid in dirty or units.get(uid) is not rec or not rec.live() or rec.seq != seq:
                continue
            if rec.stepper is not st or st.version != version or rec.position is None:
                continue
            got.append(uid)
        return got


def guided(units: Mapping[str, UnitRecord]) -> tuple[list[UnitRecord], list[bool]]:
    """The units a change may re-judge (each with a stepper and a position), and which of them are wide:
    escaping or deliberating, they may leave their corridor (``reach.reached``)."""
    recs = [r for r in units.values() if r.stepper is not None and r.position is not None]
    wide = [r.stepper.escaping or r.job is not None or r.stepper.pending is not None for r in recs]  # type: ignore[union-attr]
    return recs, wide


@dataclass(frozen=True, eq=False)
class Corridors:
    """The guided units' corridors when a threat's window was asked, with the threat it replaces.

    ``before`` is the threat then in force under the same id (its term goes
    when the new one takes force), seen through ``before_window``.
    """

    ids: tuple[str, ...]
    ends: np.ndarray  # (n, 4): start x, y, goal x, y (``reach.corridor_ends``)
    wide: np.ndarray  # (n,) bool
    intensity: str
    before: Threat | None = None
    before_window: Window | None = None


def corridors(units: Mapping[str, UnitRecord], intensity: str) -> Corridors:
    """``Corridors`` of ``units`` as they stand (built on the loop, in the put's ``apply``), replacing no threat."""
    recs, wide = guided(units)
    ends = reach.corridor_ends(recs) if recs else np.zeros((0, 4))
    return Corridors(tuple(r.id for r in recs), ends, np.array(wide, dtype=bool), intensity)


@dataclass(frozen=True, eq=False)
class Judged:
    """Which of ``corridors`` a landed threat (and the one it replaces) reaches, judged off the loop."""

    threats: tuple[Threat, ...]  # the threat it replaced, if any, then the landed one
    corridors: Corridors
    hit: np.ndarray  # (n,) bool, by ``corridors.ids``
    index: dict[str, int]  # unit id -> its row in ``corridors``


def judge(c: Corridors, target: Threat, window: Window | None) -> Judged | None:
    """``reach.reached_at`` over ``c`` for ``target`` seen through ``window`` (and ``c.before``); ``None``: it failed
    (the landing tests every unit then)."""

    def sight(threat: object, box: tuple[float, float, float, float]) -> Window | None:
        return window if threat is target else c.before_window if threat is c.before else None

    threats = (target,) if c.before is None else (c.before, target)
    try:
        hit = reach.reached_at(c.ends, threats, c.intensity, (), sight, c.wide)
    except Exception:
        return None
    return Judged(threats, c, hit, {uid: i for i, uid in enumerate(c.ids)})


def answered(ground: Ground, ask: SightAsk) -> SightLanded:
    """The window ``ask`` wants (``terrain.answer``) and, when it carries corridors, their reach judged with it.

    Raises:
        Exception: whatever the sweep raises (the window never lands; the world's ``sight`` timer acts).
    """
    landed = answer(ground, ask)
    if ask.corridors is None:
        return landed
    return dataclasses.replace(landed, judged=judge(ask.corridors, ask.target, landed.window))


def reached_with(
    judged: Sequence[Judged],
    recs: list[UnitRecord],
    wide: list[bool],
    touched: list[Threat],
    intensity: str,
    zones: Sequence[tuple[float, float, float, float]],
    sight: Sight | None,
) -> list[bool]:
    """``reach.reached`` of ``recs``, taking each ``judged`` verdict for the units whose corridor is as it was judged.

    A verdict counts when its landed threat is among ``touched`` (the very
    object), and stands for its threats; a unit guided since, or whose
    corridor or width changed, is tested afresh for them, and every unit
    for the other touched threats and the ``zones``.  If a test fails, every
    unit counts as reached: dearer, never wrong.
    """
    usable = [j for j in judged if any(t is j.threats[-1] for t in touched)]
    if not usable or not recs:
        return reach.reached(recs, touched, intensity, zones, sight, wide)
    try:
        flat, wide_a = reach.corridor_ends(recs), np.array(wide, dtype=bool)
        hit = np.zeros(len(recs), dtype=bool)
        rest: list[Any] = list(touched)
        for j in usable:
            c = j.corridors
            idx = np.fromiter((j.index.get(r.id, -1) for r in recs), dtype=np.intp, count=len(recs))
            same = idx >= 0
            at = idx[same]
            same[same] = (c.ends[at] == flat[same]).all(axis=1) & (c.wide[at] == wide_a[same])
            hit[same] |= j.hit[idx[same]]
            if not same.all():  # guided or moved since it was asked: tested here, for the verdict's threats
                again = ~same
                hit[again] |= reach.reached_at(flat[again], j.threats, intensity, (), sight, wide_a[again])
            rest = [t for t in rest if not any(t is u for u in j.threats)]
        if rest or len(zones):
            hit |= reach.reached_at(flat, rest, intensity, zones, sight, wide_a)
        got: list[bool] = hit.tolist()
        return got
    except Exception:
        return [True] * len(recs)
