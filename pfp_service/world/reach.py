"""Which units a change of threats or zones can reach: each corridor tested at once, over terrain by sight.

``reached`` is what a contingency costs: only the units it returns are
re-judged and re-directed (``World._world_changed``); every other unit's
direction is unchanged within the cull bound.  ``reached_at`` is the same
test on plain arrays (``corridor_ends``), so a threat's landing can be judged
off the loop with its window (``wave.judge``).  Pure values: no clock, no I/O.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from pfp_service.core import Threat, ThreatField
from pfp_service.core.cull import RELATIVE_BOUND, corridors_meet, influence_boxes
from pfp_service.core.visibility import Sight

if TYPE_CHECKING:
    from pfp_service.world.units import UnitRecord

__all__ = [
    "SEEN_SAMPLES",
    "SEEN_STEP_M",
    "WIDE_BLOCK",
    "WIDE_REACH",
    "WIDE_SAMPLES",
    "ZONE_REACH",
    "corridor_ends",
    "reached",
    "reached_at",
]

# over terrain, a corridor is looked at every this many metres (at most this many points) for a threat's sight
SEEN_STEP_M = 25.0
SEEN_SAMPLES = 513
ZONE_REACH = 0.25  # a zone's box is widened by this share of its diagonal: its barrier's reach, generously
# an escaping or deliberating unit may leave its straight corridor (an escape's detour, a foresight's
# path): its corridor is then the box of its position and goal, widened by this share of their distance
WIDE_REACH = 0.5
WIDE_SAMPLES = 24  # over terrain, that box is looked at on this many points a side for a threat's sight
WIDE_BLOCK = 256  # ... this many units' points at once (4.7 MB of points and levels)


def reached(
    guided: list[UnitRecord],
    touched: list[Threat],
    intensity: str,
    zones: Sequence[tuple[float, float, float, float]] = (),
    sight: Sight | None = None,
    wide: Sequence[bool] | None = None,
) -> list[bool]:
    """Which units (each with a stepper and a position) a change of the ``touched`` threats or zones can reach.

    A unit is reached when a touched threat's influence box (where it is not
    culled, ``cull.influence_boxes``), or a touched zone's box (``zones``:
    ``(xmin, ymin, xmax, ymax)``, widened by ``ZONE_REACH`` of its diagonal for
    the barrier that bends descent away near its edge), meets the unit's
    corridor to its goal (``cull.corridors_meet``).  Over terrain (``sight``) a
    threat reaches only a unit it can see somewhere along that corridor
    (``_seen``): behind a ridge its term is zero, and so is its pull on the
    unit's direction.  Every other unit's direction is unchanged within the
    cull bound.  A unit marked ``wide`` (escaping or deliberating: it may
    leave its corridor) is reached when a touched threat or zone meets the
    box of its position and goal widened by ``WIDE_REACH`` of their
    distance, and over terrain when the threat sees somewhere in that box
    (``_seen_in_boxes``).  If the vectorised test fails, every unit counts as
    reached: dearer, never wrong.
    """
    if not guided:
        return []
    try:
        hit: list[bool] = reached_at(corridor_ends(guided), touched, intensity, zones, sight, wide).tolist()
        return hit
    except Exception:
        return [True] * len(guided)


def corridor_ends(guided: Sequence[UnitRecord]) -> np.ndarray:
    """``(n, 4)``: each unit's start and goal (``x, y, gx, gy``), in one pass: a wave's first look at every unit."""
    n = len(guided)
    ends = itertools.chain.from_iterable((*r.position, *r.stepper.goal) for r in guided)  # type: ignore[misc, union-attr]
    return np.fromiter(ends, dtype=float, count=4 * n).reshape(n, 4)


def reached_at(
    flat: np.ndarray,
    touched: Sequence[Threat],
    intensity: str,
    zones: Sequence[tuple[float, float, float, float]] = (),
    sight: Sight | None = None,
    wide: Sequence[bool] | np.ndarray | None = None,
) -> np.ndarray:
    """``reached`` over corridors given as ``(n, 4)`` ends (``corridor_ends``): pure arrays, any thread.

    Raises:
        Exception: whatever the field raises (``reached`` counts every unit reached then).
    """
    n = len(flat)
    starts, goals = flat[:, :2], flat[:, 2:]
    hit = np.zeros(n, dtype=bool)
    if touched:
        boxes = influence_boxes(ThreatField(touched, intensity).packed)  # type: ignore[arg-type]
        if sight is None:
            hit |= corridors_meet(starts, goals, boxes)
        else:
            for threat, box in zip(touched, boxes, strict=True):
                near = corridors_meet(starts, goals, box[None, :])
                if near.any():
                    near[near] = _seen(threat, box, starts[near], goals[near], intensity, sight)
                    hit |= near
    if len(zones):
        zb = np.array(zones, dtype=float).reshape(-1, 4)
        pad = ZONE_REACH * np.hypot(zb[:, 2] - zb[:, 0], zb[:, 3] - zb[:, 1])[:, None]
        hit |= corridors_meet(starts, goals, zb + np.hstack([-pad, -pad, pad, pad]))
    if wide is not None and np.any(wide):
        w = np.flatnonzero(np.asarray(wide, dtype=bool) & ~hit)
        hit[w] = _wide(starts[w], goals[w], touched, intensity, zones, sight)
    return hit


def _wide(
    starts: np.ndarray,
    goals: np.ndarray,
    touched: Sequence[Threat],
    intensity: str,
    zones: Sequence[tuple[float, float, float, float]],
    sight: Sight | None,
) -> np.ndarray:
    """``reached`` for units that may leave their corridor: their boxes widened by ``WIDE_REACH``."""
    pad = WIDE_REACH * np.hypot(*(goals - starts).T)[:, None]
    lo, hi = np.minimum(starts, goals) - pad, np.maximum(starts, goals) + pad
    units = np.hstack([lo, hi])  # (n, 4): x0, y0, x1, y1
    hit = np.zeros(len(units), dtype=bool)
    if len(zones):
        zb = np.array(zones, dtype=float).reshape(-1, 4)
        zpad = ZONE_REACH * np.hypot(zb[:, 2] - zb[:, 0], zb[:, 3] - zb[:, 1])[:, None]
        hit |= _boxes_meet(units, zb + np.hstack([-zpad, -zpad, zpad, zpad])).any(axis=1)
    if touched:
        boxes = influence_boxes(ThreatField(touched, intensity).packed)  # type: ignore[arg-type]
        meet = _boxes_meet(units, boxes)  # (n, threats)
        for j, threat in enumerate(touched):
            w = np.flatnonzero(meet[:, j] & ~hit)
            if len(w):
                hit[w] = (
                    True if sight is None else _seen_in_boxes(threat, boxes[j], units[w], intensity, sight)
                )
    return hit


def _boxes_meet(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(len(a), len(b))``: whether box ``a[i]`` meets box ``b[j]`` (``x0, y0, x1, y1``)."""
    return (
        (a[:, None, 0] <= b[None, :, 2])
        & (b[None, :, 0] <= a[:, None, 2])
        & (a[:, None, 1] <= b[None, :, 3])
        & (b[None, :, 1] <= a[:, None, 3])
    )


def _seen_in_boxes(
    threat: Threat, box: np.ndarray, units: np.ndarray, intensity: str, sight: Sight
) -> np.ndarray:
    """Whether ``threat`` sees anywhere in the part of each unit's box (``(n, 4)``) within its own ``box``.

    Each part is looked at on ``WIDE_SAMPLES`` points a side, all units' at
    once under one field blind and one masked (``_seen``'s bound): a wave
    re-judges hundreds of deliberating units, and a field a unit cost a
    millisecond each.
    """
    blind_f = ThreatField([threat], intensity)  # type: ignore[arg-type]
    masked_f = ThreatField([threat], intensity, sight=sight)  # type: ignore[arg-type]
    lo = np.maximum(units[:, :2], box[None, :2])  # (n, 2): x0, y0 of each part
    hi = np.minimum(units[:, 2:], box[None, 2:])
    t = np.linspace(0.0, 1.0, WIDE_SAMPLES)
    xs = lo[:, None, 0] + t[None, :] * (hi[:, 0] - lo[:, 0])[:, None]  # (n, k)
    ys = lo[:, None, 1] + t[None, :] * (hi[:, 1] - lo[:, 1])[:, None]
    k, out = WIDE_SAMPLES, np.zeros(len(units), dtype=bool)
    for a in range(0, len(units), WIDE_BLOCK):  # the points' memory bounded, whatever the fleet
        pts = np.empty((len(units[a : a + WIDE_BLOCK]), k, k, 2))
        pts[..., 0] = xs[a : a + WIDE_BLOCK, None, :]
        pts[..., 1] = ys[a : a + WIDE_BLOCK, :, None]
        blind, masked = blind_f.level(pts), masked_f.level(pts)
        out[a : a + WIDE_BLOCK] = ((blind > 0.0) & (masked >= RELATIVE_BOUND * blind)).any(axis=(1, 2))
    return out


def _seen(
    threat: Threat, box: np.ndarray, starts: np.ndarray, goals: np.ndarray, intensity: str, sight: Sight
) -> np.ndarray:
    """Whether ``threat`` sees each corridor (start to goal) anywhere inside its influence box.

    The corridor is sampled every ``SEEN_STEP_M`` (at most ``SEEN_SAMPLES`` points); a
    sample is seen where the masked level is at least ``RELATIVE_BOUND`` of the
    blind one (the cull's own bound on what a term may change).
    """
    length = float(np.hypot(*(goals - starts).T).max(initial=0.0))
    k = int(min(SEEN_SAMPLES, max(2, math.ceil(length / SEEN_STEP_M) + 1)))
    t = np.linspace(0.0, 1.0, k)[None, :, None]
    pts = starts[:, None, :] + t * (goals - starts)[:, None, :]  # (units, k, 2)
    inside = (
        (pts[..., 0] >= box[0]) & (pts[..., 0] <= box[2]) & (pts[..., 1] >= box[1]) & (pts[..., 1] <= box[3])
    )
    blind = ThreatField([threat], intensity).level(pts)  # type: ignore[arg-type]
    masked = ThreatField([threat], intensity, sight=sight).level(pts)  # type: ignore[arg-type]
    return np.asarray((inside & (blind > 0.0) & (masked >= RELATIVE_BOUND * blind)).any(axis=1))
