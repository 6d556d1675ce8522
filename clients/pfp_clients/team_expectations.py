"""A team's expectations judged on the watched tracks: separation kept, only cleared ground entered, the link kept.

Each takes the tracks ``watch.Watch`` saw (``(t, x, y)`` per unit, in script
seconds) and says whether the expectation held, with the figure that decides
it.  The other unit's position at one of this unit's reports is interpolated
between its own reports; a report before the other's first or after its last
is not judged (the unit had no partner then).  Independent of the planner's
own team logic: what is judged is where the units went.
"""

from __future__ import annotations

import numpy as np

from pfp_clients.script import Expect

__all__ = ["keeps_from", "link_to", "only_cleared_by"]

Track = list[tuple[float, float, float]]


def _at_times(other: Track, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``other``'s positions at ``times`` (linear between its reports) and which of ``times`` it covers."""
    o = np.asarray(other, dtype=float)
    covered = (times >= o[0, 0]) & (times <= o[-1, 0])
    xy = np.column_stack([np.interp(times, o[:, 0], o[:, 1]), np.interp(times, o[:, 0], o[:, 2])])
    return xy, covered


def _pairs(track: Track, other: Track) -> tuple[np.ndarray, np.ndarray] | None:
    """This unit's positions and the other's at the same times, where both are known; ``None``: nowhere."""
    if not track or not other:
        return None
    me = np.asarray(track, dtype=float)
    xy, covered = _at_times(other, me[:, 0])
    if not covered.any():
        return None
    return me[covered, 1:], xy[covered]


def keeps_from(e: Expect, track: Track, other: Track) -> tuple[bool, str]:
    """``e.unit`` never closer to ``e.keeps_from`` than ``e.at_least_m``."""
    assert e.keeps_from is not None and e.at_least_m is not None
    pairs = _pairs(track, other)
    if pairs is None:
        return False, f"{e.unit} and {e.keeps_from} were never seen at the same time"
    d = np.hypot(*(pairs[0] - pairs[1]).T)
    i = int(np.argmin(d))
    return bool(
        d[i] >= e.at_least_m
    ), f"closest {d[i]:.2f} m, at ({pairs[0][i][0]:.1f}, {pairs[0][i][1]:.1f})"


def _off(p: np.ndarray, line: np.ndarray) -> float:
    """How far ``p`` is from the polyline ``line`` (one point: from that point)."""
    if len(line) == 1:
        return float(np.hypot(*(p - line[0])))
    a, b = line[:-1], line[1:]
    ab = b - a
    sq = (ab * ab).sum(axis=1)
    t = np.clip(((p - a) * ab).sum(axis=1) / np.where(sq > 0.0, sq, 1.0), 0.0, 1.0)
    near = a + ab * t[:, None]
    return float(np.hypot(near[:, 0] - p[0], near[:, 1] - p[1]).min())


def only_cleared_by(e: Expect, track: Track, lead: Track) -> tuple[bool, str]:
    """Once ``e.unit`` is in ``e.only_cleared_by``'s corridor, each of its reports lies on ground the lead crossed before it.

    The corridor at time ``t`` is the lead's track up to ``t`` (its reports joined by straight lines),
    ``corridor_m / 2`` either side; reports before the unit first entered it are its way in.
    """
    assert e.only_cleared_by is not None
    if len(track) < 2 or not lead:
        return False, "too few states of the units were seen to judge"
    half = e.corridor_m / 2.0
    lead_xy = np.asarray([(x, y) for _t, x, y in lead], dtype=float)
    lead_t = np.asarray([t for t, _x, _y in lead])
    entered = None
    for t, x, y in track:
        n = int(np.searchsorted(lead_t, t, side="right"))
        if n == 0:
            continue
        off = _off(np.array([x, y]), lead_xy[:n])
        if entered is None and off <= half:
            entered = t
        elif entered is not None and off > half:
            return (
                False,
                f"outside the cleared corridor at ({x:.2f}, {y:.2f}), t={t:.1f} s, {off - half:.2f} m out",
            )
    if entered is None:
        return False, f"{e.unit} never entered ground {e.only_cleared_by} had crossed"
    return True, f"every report on cleared ground from t={entered:.1f} s"


def link_to(e: Expect, track: Track, controller: Track) -> tuple[bool, str]:
    """The share of ``e.unit``'s reports within ``e.radio_range_m`` of ``e.link_to``, at least ``e.at_least_pct``."""
    assert e.link_to is not None and e.at_least_pct is not None
    pairs = _pairs(track, controller)
    if pairs is None:
        return False, f"{e.unit} and {e.link_to} were never seen at the same time"
    d = np.hypot(*(pairs[0] - pairs[1]).T)
    pct = 100.0 * float((d <= e.radio_range_m).mean())
    return pct >= e.at_least_pct, f"in range {pct:.1f} % of {len(d)} reports (farthest {d.max():.1f} m)"
