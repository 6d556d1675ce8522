"""Which units outside a team a team preview replays with it: those whose reach comes near the team's.

Dispersion and right of way are the only rules by which a unit outside a
team changes a member's direction, and both act within ``REACH`` of a
pair's separation (``core.dispersion``; right of way within ``YIELD_AT``,
fewer).  So, with dispersion on, an outsider is relevant when its reach over
the preview's horizon comes within ``REACH`` times the pair's separation of
a member's: a reach is the straight segment from where the unit is toward
its goal, as far as its speed takes it within the horizon (the whole way
when it reports none), or the point where it is for a unit the planner does
not guide.  The relevant ones are taken nearest first, at most
``MAX_PREVIEW_OUTSIDERS``; the rest are counted, so a reader knows the bound.
With dispersion off no outsider can change a member's track: none is taken.

Not judged: routes that bend round a threat or a zone (a reach is the
straight line), timing (two reaches that meet at different times still
count, which only costs replay steps), and chains (an outsider that only
pushes another outsider into the team's way).

Cost, on the planner's loop: one pass over the world's unit records and a
few vectorised operations over those inside the team's reaches' bounding
box; no record is copied but the ones taken (``team_preview.seed``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from itertools import chain

import numpy as np

from pfp_service.core.dispersion import REACH
from pfp_service.wire.messages import MAX_PREVIEW_OUTSIDERS
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.units import UnitRecord

__all__ = ["Reach", "guided", "nearby", "reach", "segment_gaps"]

Point = tuple[float, float]
Reach = tuple[Point, Point]  # a segment: where the unit is, and how far toward its goal it may get


def guided(rec: UnitRecord) -> bool:
    """Whether the replay moves ``rec`` toward its goal (else it holds where it is)."""
    return rec.goal is not None and rec.stepper is not None and rec.progress.speed_mps > 0.0


def reach(at: Point, goal: Point | None, speed_mps: float, horizon_s: float) -> Reach:
    """The straight segment from ``at`` toward ``goal``, cut at ``speed_mps * horizon_s`` (0: the whole way)."""
    if goal is None:
        return (at, at)
    dx, dy = goal[0] - at[0], goal[1] - at[1]
    far = math.hypot(dx, dy)
    go = far if speed_mps <= 0.0 else min(far, speed_mps * horizon_s)
    if not far > 0.0 or not math.isfinite(go):
        return (at, at) if not far > 0.0 else (at, goal)
    return (at, (at[0] + dx * go / far, at[1] + dy * go / far))


def nearby(
    units: Mapping[str, UnitRecord],
    team: frozenset[str],
    reaches: Sequence[Reach],
    settings: DispersionSettings,
    horizon_s: float,
    cap: int = MAX_PREVIEW_OUTSIDERS,
) -> tuple[list[str], int]:
    """The units outside ``team`` whose reach comes near one of ``reaches``, nearest first, and how many more did.

    Args:
        units: the world's unit records (read, never written).
        team: the team's members.
        reaches: the members' reaches (``reach``).
        settings: the mission's dispersion (off: no outsider is taken).
        horizon_s: the preview's horizon.
        cap: at most this many are taken.

    Returns:
        The ids taken (at most ``cap``) and how many more were near but left out.
    """
    if not settings.enabled or not reaches or cap < 0:
        return [], 0
    with np.errstate(all="ignore"):  # a far-off or absurd position gives no gap (NaN), not a warning
        return _nearby(units, team, reaches, settings, horizon_s, cap)


def _nearby(
    units: Mapping[str, UnitRecord],
    team: frozenset[str],
    reaches: Sequence[Reach],
    settings: DispersionSettings,
    horizon_s: float,
    cap: int,
) -> tuple[list[str], int]:
    sep = settings.separation
    widest_member = max(sep(u) for u in team)
    members = np.array(reaches, dtype=float).reshape(-1, 4)  # x0 y0 x1 y1
    # one pass over the records, in the loop: what a reach needs, and nothing copied
    nan = (math.nan, math.nan)
    recs = [r for r in units.values() if r.position is not None and not r.stale and r.id not in team]
    if not recs:
        return [], 0
    rows = np.fromiter(
        chain.from_iterable(
            [
                (
                    *r.position,  # type: ignore[misc]
                    *(r.goal.position if r.goal is not None and r.stepper is not None else nan),
                    r.progress.speed_mps,
                )
                for r in recs
            ]
        ),
        dtype=np.float64,
        count=5 * len(recs),
    ).reshape(-1, 5)
    at, goal = rows[:, :2], rows[:, 2:4]
    stands = np.isnan(goal[:, 0])
    run = np.where(stands, 0.0, rows[:, 4]) * horizon_s  # 0: it stands (``guided``)
    way = np.where(stands[:, None], 0.0, goal - at)
    far = np.hypot(way[:, 0], way[:, 1])
    go = np.where(run > 0.0, np.minimum(far, run), 0.0)
    step = np.divide(go, far, out=np.zeros_like(far), where=far > 0.0)
    outs = np.concatenate([at, at + way * step[:, None]], axis=1)
    # the reaches whose box meets the members' box grown by the widest reach, then the exact gaps
    classes = {settings.default_class, *settings.classes.values()}  # the classes in the mission
    closest = REACH * widest_member  # within it, an outsider of any class is near
    widest = REACH * max(max(settings.separation_m[c] for c in classes), widest_member)
    lo = np.minimum(members[:, :2], members[:, 2:]).min(axis=0) - widest
    hi = np.maximum(members[:, :2], members[:, 2:]).max(axis=0) + widest
    box = np.flatnonzero(
        np.all(
            (np.minimum(outs[:, :2], outs[:, 2:]) <= hi) & (np.maximum(outs[:, :2], outs[:, 2:]) >= lo),
            axis=1,
        )
    )
    if not len(box):
        return [], 0
    gap = segment_gaps(outs[box], members).min(axis=1)
    near = np.full(len(box), closest)
    for k in np.flatnonzero((gap >= closest) & (gap < widest)).tolist():  # wider than every member
        near[k] = REACH * max(sep(recs[box[k]].id), widest_member)
    hit = np.flatnonzero(gap < near)
    first = hit[np.argsort(gap[hit], kind="stable")[:cap]]
    taken = sorted((float(gap[k]), recs[box[k]].id) for k in first.tolist())
    return [u for _, u in taken], len(hit) - len(first)


def segment_gaps(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(len(a), len(b))``: the least distance between each segment of ``a`` and each of ``b`` (rows x0 y0 x1 y1)."""
    p0, p1 = a[:, None, :2], a[:, None, 2:]
    q0, q1 = b[None, :, :2], b[None, :, 2:]
    ends = np.minimum(
        np.minimum(_point_gaps(p0, q0, q1), _point_gaps(p1, q0, q1)),
        np.minimum(_point_gaps(q0, p0, p1), _point_gaps(q1, p0, p1)),
    )
    # segments that cross: each one's ends on either side of the other's line
    d1, d2 = _cross(q0, q1, p0), _cross(q0, q1, p1)
    d3, d4 = _cross(p0, p1, q0), _cross(p0, p1, q1)
    crossing = (d1 * d2 < 0.0) & (d3 * d4 < 0.0)
    gaps: np.ndarray = np.where(crossing, 0.0, ends)
    return gaps


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product of ``o a`` and ``o b``: which side of the line ``o a`` ``b`` is on."""
    ax, ay, bx, by = (
        a[..., 0] - o[..., 0],
        a[..., 1] - o[..., 1],
        b[..., 0] - o[..., 0],
        b[..., 1] - o[..., 1],
    )
    side: np.ndarray = ax * by - ay * bx
    return side


def _point_gaps(p: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """The distance from each point ``p`` to the segment ``q0 q1`` (broadcast)."""
    d = q1 - q0
    dd = (d * d).sum(axis=-1)
    t = np.where(dd > 0.0, ((p - q0) * d).sum(axis=-1) / np.where(dd > 0.0, dd, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    c = q0 + t[..., None] * d
    gaps: np.ndarray = np.hypot(p[..., 0] - c[..., 0], p[..., 1] - c[..., 1])
    return gaps
