"""Dispersion's last word on a moving direction: it never takes a unit within ``KEEP`` separations of another.

Each direction's ray is tested against every neighbour's disc of ``KEEP``
times the pair's separation, in one vectorised pass, and its reach is cut at
the first disc's edge.  A unit already on a disc's edge whose direction
leans into it would be cut to nothing, however slightly it leans: a row of
units abreast at that distance, each leaning towards a neighbour, would
then hold still for ever (and a unit yielding to one of them with it).
Such a unit slides instead: it goes along the disc (its direction less its
component into it), which takes it no nearer that neighbour, when that
slide is at least ``SLIDE`` of its direction and enters no other disc.

``cut`` also says which units it left cut to nothing, and by whom: two units
each stopped by the other's disc hold each other (``dispersion`` makes two
going round units at rest so one deadlock).
"""

from __future__ import annotations

import math

import msgspec
import numpy as np

from pfp_service.core.dispersion import NeighbourIndex
from pfp_service.wire import Direction

__all__ = ["KEEP", "SLIDE", "cut"]

KEEP = 1.1  # no direction drives a unit within this many separations of another
# a unit on a disc's edge slides along it when the slide keeps this share of its direction (30 degrees
# or more off the line into the neighbour): straighter at it, it holds, as in a queue behind a unit
SLIDE = 0.5
_GRAZE_M = 1e-6  # along a disc's tangent: rounding, not a way into it


def cut(
    index: NeighbourIndex, rows: np.ndarray, directions: list[Direction], go: list[int]
) -> list[tuple[int, int]]:
    """Cut (or slide) each of ``directions[go]``, the units at ``index`` rows ``rows``, in place.

    Returns each unit left cut to nothing (its position in ``directions``)
    with the row of every neighbour whose disc stops it, one pair each.

    Args:
        index: this tick's neighbour index.
        rows: each moving direction's row in ``index``.
        directions: the tick's directions; those at ``go`` have a non-zero vector.
        go: the positions in ``directions`` of the moving ones, in the order of ``rows``.
    """
    vec = np.array([directions[k].vector for k in go], dtype=float).reshape(-1, 2)
    at = np.full(len(index.points), -1, dtype=np.intp)
    at[rows] = np.arange(len(rows))
    i, j, pair_s = index.near_seps(rows)
    n = at[i]
    rel = index.points[j] - index.points[i]
    keep_m = KEEP * pair_s
    safe, along, enter = _rays(rel, vec[n], keep_m, n, len(go))
    slid = _slides(rel, vec, keep_m, n, along, enter, safe)
    for m in np.flatnonzero(np.isfinite(safe)).tolist():
        k, reach = go[m], float(safe[m])
        d = directions[k]
        if m in slid:
            v, reach = slid[m]
            d = msgspec.structs.replace(
                d, vector=v, heading_deg=math.degrees(math.atan2(v[0], v[1])) % 360.0, true_bearing_deg=None
            )
        if math.isfinite(reach) and (d.reach_m is None or reach < d.reach_m):
            d = msgspec.structs.replace(d, reach_m=reach)
        directions[k] = d
    held = (enter <= _GRAZE_M) & (safe[n] <= _GRAZE_M)
    return [(go[m], jj) for m, jj in zip(n[held].tolist(), j[held].tolist()) if m not in slid]


def _rays(
    rel: np.ndarray, vec: np.ndarray, keep_m: np.ndarray, n: np.ndarray, count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each ray's distance to the first disc it enters (``inf``: none); each pair's lean into the disc and entry.

    A pair's ``along`` is how far along the ray its neighbour lies; its
    entry is ``inf`` when the ray does not enter its disc.
    """
    along = (rel * vec).sum(axis=1)
    across2 = (rel * rel).sum(axis=1) - along * along
    hit = (along > _GRAZE_M) & (across2 < keep_m * keep_m)
    enter = np.full(len(rel), np.inf)
    enter[hit] = np.maximum(along[hit] - np.sqrt(np.maximum(keep_m[hit] ** 2 - across2[hit], 0.0)), 0.0)
    safe = np.full(count, np.inf)
    np.minimum.at(safe, n[hit], enter[hit])
    return safe, along, enter


def _slides(
    rel: np.ndarray,
    vec: np.ndarray,
    keep_m: np.ndarray,
    n: np.ndarray,
    along: np.ndarray,
    enter: np.ndarray,
    safe: np.ndarray,
) -> dict[int, tuple[tuple[float, float], float]]:
    """The units cut to nothing that can slide: each one's way along the disc it leans into most, and how far.

    How far is the slide's own cut against every disc (``inf``: none); a
    slide that would enter another disc at once is no slide, and the unit holds.
    """
    stuck = (enter <= _GRAZE_M) & (safe[n] <= _GRAZE_M)
    if not stuck.any():
        return {}
    p = np.flatnonzero(stuck)
    lean = along[p] / np.hypot(rel[p, 0], rel[p, 1])
    order = np.lexsort((-lean, n[p]))  # each unit's most leaned-into disc first
    first = order[np.unique(n[p][order], return_index=True)[1]]
    units, p, lean = n[p][first], p[first], lean[first]
    normal = rel[p] / np.hypot(rel[p, 0], rel[p, 1])[:, None]
    slide = vec[units] - lean[:, None] * normal
    size = np.hypot(slide[:, 0], slide[:, 1])
    ok = size >= SLIDE * np.hypot(vec[units, 0], vec[units, 1])
    units, slide = units[ok], slide[ok] / size[ok, None]
    if not len(units):
        return {}
    way = np.zeros_like(vec)
    way[units] = slide
    mine = np.isin(n, units)  # every pair of the sliding units, against their new ways
    again, _, _ = _rays(rel[mine], way[n[mine]], keep_m[mine], n[mine], len(vec))
    return {
        u: ((float(v[0]), float(v[1])), float(again[u]))
        for u, v in zip(units.tolist(), slide.tolist())
        if again[u] > _GRAZE_M
    }
