"""Crowds for ``pfp bench dispersion`` and its tests: seeded scenarios, and the in-process world driven through them.

``simulate`` drives a sans-I/O ``World`` as the live service would be
driven, without Zenoh: every unit reports its position (``StateReported``)
each ``dt_s`` of simulated time, one ``apply`` answers the batch, and each
unit then drives along its direction at its own speed, never past how far
the direction holds (``reach_m``), as the README's vehicle does.
Deliberation jobs run between ticks (as the service's workers do, off the
loop) and come back as ``Deliberated`` inputs in the next batch; the tick's
CPU is the ``apply`` alone.  Every figure is measured on the tracks, not
taken from the world: the nearest friendly unit of each unit at each tick
(a k-d tree over the true positions), arrivals, and how long units held.
"""

from __future__ import annotations

import dataclasses
import math
import random
import time
from dataclasses import dataclass, field

import numpy as np

from pfp_service.wire import (
    DeadlockEvent,
    Direction,
    DirectionStatus,
    Goal,
    TeamUpdate,
    ThreatUpdate,
    UnitKind,
    UnitState,
)
from pfp_service.world import events as ev
from pfp_service.world.separations import DispersionSettings
from pfp_service.world.world import World, WorldSettings

__all__ = [
    "Crowd",
    "Outcome",
    "converging",
    "crowded_goal",
    "gaps",
    "head_on",
    "jam",
    "lane",
    "near_its_goal",
    "one_gap",
    "pinned",
    "simulate",
    "wall",
]

_MOVES = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING, DirectionStatus.YIELDING)


@dataclass(frozen=True)
class Crowd:
    """A seeded scenario: each unit's start, goal and kind (``manned``/``unmanned``), the threats, the speed."""

    name: str
    starts: list[tuple[float, float]]
    goals: list[tuple[float, float]]
    kinds: list[str]
    threats: dict[str, ThreatUpdate]
    speed_mps: float = 5.0
    limit_s: float = 1800.0  # simulated time at most
    teams: dict[str, TeamUpdate] = field(default_factory=dict)

    def ids(self) -> list[str]:
        return [f"u{k:04d}" for k in range(len(self.starts))]


@dataclass
class Outcome:
    """What a run did, measured on its tracks."""

    arrived_s: dict[str, float] = field(default_factory=dict)  # unit -> simulated time of arrival
    trapped: set[str] = field(default_factory=set)
    closest_m: float = math.inf  # the closest two units came, over the whole run
    closest_share: float = math.inf  # ... as a share of the pair's separation (1: exactly at it)
    closest_at: tuple[float, str, str] | None = None  # when, and which two
    deadlocks: int = 0
    longest_hold_s: float = 0.0  # the longest a unit yielded (held or backed off) without a break
    longest_deadlock_s: float = 0.0  # the longest such stretch among those with a deadlock in them
    still_holding: int = 0
    longest_clearing_s: float = 0.0  # the longest from a deadlock's start until both its units moved on
    not_cleared: int = 0  # deadlocks whose units had not moved on when the run ended
    tick_cpu_s: list[float] = field(default_factory=list)  # each apply's CPU time
    shadow_cpu_s: list[float] = field(default_factory=list)  # the shadow world's, on the same inputs
    states: int = 0  # state reports applied
    sim_s: float = 0.0


def gaps(n: int = 200, seed: int = 1, gap_m: float = 240.0) -> Crowd:
    """``n`` vehicles from the south to the north through a line of threats with three gaps.

    Starts on a jittered grid 90 m apart (clear of 50 m), goals a grid 3 km
    north, 154 m by 130 m apart (the front row's the farthest, as a column marches), beyond a line of threats along y = 0 facing south,
    broken by three gaps of ``gap_m`` at x = -1000, 0 and 1000.  A fifth of
    the units are manned, chosen by the seed.
    """
    rng = random.Random(seed)
    cols = 20
    rows = math.ceil(n / cols)
    starts, goals = [], []
    for k in range(n):
        r, c = divmod(k, cols)
        x = (c - (cols - 1) / 2) * 110.0
        starts.append((x + rng.uniform(-10, 10), -1500.0 - 90.0 * r + rng.uniform(-10, 10)))
        goals.append((x * 1.4, 1500.0 + 130.0 * (rows - 1 - r)))  # the front row goes farthest
    kinds = ["manned" if rng.random() < 0.2 else "unmanned" for _ in range(n)]
    threats = wall((-1000.0, 0.0, 1000.0), gap_m)
    return Crowd(f"{n} units through 3 gaps", starts, goals, kinds, threats)


def converging(n: int = 1000, seed: int = 2) -> Crowd:
    """``n`` vehicles converging: a wide grid 200 m apart driving to one 0.6 its size, 4 km north.

    Each unit keeps its place in the grid (north rows to north rows), so no
    unit must cross ground its arrived neighbours hold; the goals, 120 m
    apart, leave a way between two arrived units that keeps the separation
    and its margin (2 x 1.1 x 50 m: goals any closer wall the inner ones in).  A few threats stand in the middle; a fifth are manned.
    """
    rng = random.Random(seed)
    cols = 40
    rows = math.ceil(n / cols)
    starts, goals = [], []
    for k in range(n):
        r, c = divmod(k, cols)
        x, y = (c - (cols - 1) / 2) * 200.0, (r - (rows - 1) / 2) * 200.0
        starts.append((x + rng.uniform(-20, 20), y - 3000.0 + rng.uniform(-20, 20)))
        goals.append((x * 0.6, y * 0.6 + 1000.0))
    kinds = ["manned" if rng.random() < 0.2 else "unmanned" for _ in range(n)]
    threats = {
        f"t{k}": ThreatUpdate(
            position=(rng.uniform(-2500, 2500), rng.uniform(-1200, -600)),
            facing_deg=180.0,
            sigma_range=150.0,
            sigma_lateral=80.0,
            skew=2.0,
        )
        for k in range(6)
    }
    return Crowd(f"{n} units, converging goals", starts, goals, kinds, threats)


def simulate(
    crowd: Crowd,
    dispersion: DispersionSettings | None,
    dt_s: float = 1.0,
    lookahead: int = 5,
    limit_s: float | None = None,
    record: list[tuple[float, Direction]] | None = None,
    shadow: DispersionSettings | None = None,
    tracks: list[np.ndarray] | None = None,
    locks: list[tuple[float, DeadlockEvent]] | None = None,
) -> Outcome:
    """Drive ``crowd`` through a world with ``dispersion`` (``None``: off) until every unit rests or time is up.

    ``record``: every direction sent, with its time, is appended to it.
    ``tracks``: every unit's position at each tick, ``(n, 2)`` a tick, is appended to it.
    ``locks``: every deadlock reported, with its time, is appended to it.
    ``shadow``: a second world with these settings is given the very same
    inputs each tick (its directions unused, its jobs run as the first's),
    and its ``apply`` timed in ``Outcome.shadow_cpu_s``: the cost of the two
    settings on identical inputs, in one sitting.
    """
    settings = WorldSettings(
        deliberation="deferred",
        lookahead=lookahead,
        unit_stale_s=1e9,
        unit_forget_s=None,
        dispersion=dispersion or DispersionSettings(),
    )
    world = World(settings)
    twin = None if shadow is None else World(dataclasses.replace(settings, dispersion=shadow))
    ids = crowd.ids()
    n = len(ids)
    pos = np.array(crowd.starts, dtype=float)
    sep = np.array([settings.dispersion.separation(u) for u in ids])
    kinds = [UnitKind(k) for k in crowd.kinds]
    vec = np.zeros((n, 2))
    reach = np.zeros(n)
    resting = np.zeros(n, dtype=bool)
    out = Outcome()
    held_since: dict[str, float] = {}
    goals = np.array(crowd.goals, dtype=float)
    to_goal: list[np.ndarray] = []  # each unit's distance to its goal, each tick
    open_locks: list[tuple[float, list[int], np.ndarray]] = []  # (start, its two units, their distances then)
    deadlocked: set[str] = set()
    row = {u: k for k, u in enumerate(ids)}
    setup: list[ev.Input] = [ev.ThreatPut(t, u) for t, u in crowd.threats.items()]
    setup += [ev.GoalSet(u, _goal(g)) for u, g in zip(ids, crowd.goals)]
    world.apply(setup, 0.0)
    if twin is not None:
        twin.apply(setup, 0.0)
    done: list[ev.Input] = []
    twin_done: list[ev.Input] = []
    t, seq = 0.0, 0
    limit = crowd.limit_s if limit_s is None else limit_s
    from scipy.spatial import cKDTree

    while t <= limit:
        seq += 1
        to_goal.append(np.hypot(*(pos - goals).T))
        open_locks = _clearing(out, open_locks, to_goal[-1], resting, sep, t)
        inputs: list[ev.Input] = list(done)
        done_before = done
        inputs += [
            ev.StateReported(u, UnitState(position=(float(p[0]), float(p[1])), seq=seq, kind=k))
            for u, p, k in zip(ids, pos.tolist(), kinds)
        ]
        if seq == 1:  # once the units are known: a team naming units not yet seen is refused
            inputs += [ev.TeamPut(tid, team) for tid, team in crowd.teams.items()]
        c0 = time.process_time()
        o = world.apply(inputs, t)
        out.tick_cpu_s.append(time.process_time() - c0)
        out.states += n
        done = [job.run() for job in o.jobs if not job.cancelled]
        if twin is not None:
            c0 = time.process_time()
            to = twin.apply(twin_done + inputs[len(done_before) :], t)
            out.shadow_cpu_s.append(time.process_time() - c0)
            twin_done = [job.run() for job in to.jobs if not job.cancelled]
        found = [e for e in o.events if isinstance(e, DeadlockEvent)]
        out.deadlocks += len(found)
        deadlocked |= {e.unit for e in found}
        for e in found:  # from where each stood when it began
            pair = [row[e.unit], row[e.other]] if e.other in row else [row[e.unit]]
            tick = max(round((t - e.held_s) / dt_s), 0)
            open_locks.append((t - e.held_s, pair, to_goal[min(tick, len(to_goal) - 1)][pair]))
        if record is not None:
            record += [(t, d) for d in o.directions]
        if tracks is not None:
            tracks.append(pos.copy())
        if locks is not None:
            locks += [(t, e) for e in found]
        for d in o.directions:
            k = row[d.unit]
            if d.status is DirectionStatus.ARRIVED and d.unit not in out.arrived_s:
                out.arrived_s[d.unit] = t
            if d.status is DirectionStatus.TRAPPED:
                out.trapped.add(d.unit)
            elif d.status is not DirectionStatus.NO_GOAL:
                out.trapped.discard(d.unit)
            moving = d.status in _MOVES
            vec[k] = d.vector if moving else (0.0, 0.0)
            reach[k] = (d.reach_m or 0.0) if moving else 0.0
            resting[k] = d.status in (DirectionStatus.ARRIVED, DirectionStatus.TRAPPED)
            if d.status is DirectionStatus.YIELDING:
                held_since.setdefault(d.unit, t)
            elif d.unit in held_since:
                _hold_ended(out, t - held_since.pop(d.unit), d.unit in deadlocked)
                deadlocked.discard(d.unit)
        gap, share, a, b = _closest(cKDTree(pos), pos, sep)
        if share < out.closest_share:
            out.closest_at = (t, ids[a], ids[b])
        out.closest_m, out.closest_share = min(out.closest_m, gap), min(out.closest_share, share)
        if resting.all():
            break
        pos += vec * np.minimum(crowd.speed_mps * dt_s, reach)[:, None]
        t += dt_s
    for u, since in held_since.items():
        _hold_ended(out, t - since, u in deadlocked)
    out.still_holding, out.sim_s = len(held_since), t
    for start, _, _ in _clearing(out, open_locks, np.hypot(*(pos - goals).T), resting, sep, t):
        out.not_cleared += 1
        out.longest_clearing_s = max(out.longest_clearing_s, t - start)
    return out


CLEARED = 0.1  # a deadlock is cleared when each of its units is this many separations nearer its goal


def _clearing(
    out: Outcome,
    open_locks: list[tuple[float, list[int], np.ndarray]],
    to_goal: np.ndarray,
    resting: np.ndarray,
    sep: np.ndarray,
    t: float,
) -> list[tuple[float, list[int], np.ndarray]]:
    """The deadlocks not cleared yet; each cleared one's time from its start into ``out``.

    Cleared, measured on the tracks: each of the two units is nearer its goal
    than when the deadlock began, by ``CLEARED`` of its separation, or rests
    (arrived, trapped).
    """
    still = []
    for start, pair, then in open_locks:
        if np.all(resting[pair] | (to_goal[pair] <= then - CLEARED * sep[pair])):
            out.longest_clearing_s = max(out.longest_clearing_s, t - start)
        else:
            still.append((start, pair, then))
    return still


def _hold_ended(out: Outcome, held: float, deadlock: bool) -> None:
    out.longest_hold_s = max(out.longest_hold_s, held)
    if deadlock:
        out.longest_deadlock_s = max(out.longest_deadlock_s, held)


def _closest(tree: object, pos: np.ndarray, sep: np.ndarray) -> tuple[float, float, int, int]:
    """The closest pair's distance, and the smallest distance over separation of any unit to its nearest (and who)."""
    d, j = tree.query(pos, k=2)  # type: ignore[attr-defined]
    near, other = d[:, 1], j[:, 1]
    share = near / np.maximum(sep, sep[other])
    a = int(share.argmin())
    return float(near.min()), float(share[a]), a, int(other[a])


def _goal(g: tuple[float, float]) -> Goal:
    return Goal(position=g)


def wall(
    gaps_at: tuple[float, ...], gap_m: float, y: float = 0.0, span: float = 2400.0
) -> dict[str, ThreatUpdate]:
    """A line of threats along ``y`` facing south, from ``-span`` to ``span``, broken by gaps of ``gap_m``."""
    threats: dict[str, ThreatUpdate] = {}
    x = -span
    while x <= span:
        if all(abs(x - c) > gap_m / 2 + 60.0 for c in gaps_at):
            threats[f"t{len(threats)}"] = ThreatUpdate(
                position=(x, y), facing_deg=180.0, sigma_range=120.0, sigma_lateral=60.0, skew=2.0, weight=3.0
            )
        x += 60.0
    return threats


def one_gap() -> Crowd:
    """Two vehicles, manned ``u0000`` and unmanned ``u0001``, side by side, sent through one 160 m gap."""
    return Crowd(
        "two units, one gap",
        starts=[(-60.0, -700.0), (60.0, -700.0)],
        goals=[(-40.0, 700.0), (40.0, 700.0)],
        kinds=["manned", "unmanned"],
        threats=wall((0.0,), 160.0, span=1200.0),
        limit_s=600.0,
    )


def head_on(gap_m: float = 70.0) -> Crowd:
    """Two vehicles on one line, head on, ``gap_m`` apart: manned ``u0000`` north-bound, unmanned ``u0001`` south-bound."""
    return Crowd(
        "two units, head on",
        starts=[(0.0, 0.0), (0.0, gap_m)],
        goals=[(0.0, 600.0), (0.0, gap_m - 600.0)],
        kinds=["manned", "unmanned"],
        threats={},
        limit_s=600.0,
    )


def near_its_goal() -> Crowd:
    """Manned ``u0001`` 46 m short of its goal, unmanned ``u0000`` 57 m behind it, whose way north is through it.

    Each is stopped by the other: ``u0000`` yields to ``u0001``, which cannot
    come nearer its goal past ``u0000``'s disc, and both find it in one tick.
    """
    return Crowd(
        "one unit near its goal, another behind it",
        starts=[(0.0, 0.0), (10.0, 56.0)],
        goals=[(0.0, 600.0), (5.0, 10.0)],
        kinds=["unmanned", "manned"],
        threats={},
        limit_s=300.0,
    )


def pinned(gap_m: float = 320.0) -> Crowd:
    """Unmanned ``u0001`` driving north through a gap where manned ``u0000`` stands on its goal, in the middle."""
    return Crowd(
        "one unit past another at rest in a gap",
        starts=[(0.0, 0.0), (0.0, -500.0)],
        goals=[(0.0, 0.0), (0.0, 600.0)],
        kinds=["manned", "unmanned"],
        threats=wall((0.0,), gap_m, span=1200.0),
        limit_s=600.0,
    )


def crowded_goal(n: int = 8, radius_m: float = 20.0) -> Crowd:
    """``n`` vehicles from a ring 600 m out to goals on a ring ``radius_m`` across, closer than their separation."""
    starts, goals = [], []
    for k in range(n):
        a = 2.0 * math.pi * k / n
        starts.append((600.0 * math.sin(a), 600.0 * math.cos(a)))
        goals.append((radius_m * math.sin(a), radius_m * math.cos(a)))
    kinds = ["manned" if k % 3 == 0 else "unmanned" for k in range(n)]
    return Crowd(f"{n} units, one crowded goal area", starts, goals, kinds, {}, limit_s=900.0)


def lane(c_start: tuple[float, float] = (-85.0, 0.0), d_start: tuple[float, float] = (85.0, -10.0)) -> Crowd:
    """Two units at rest on their goals 133 m apart (``u0000`` manned, north; ``u0001``), and two crossing between them.

    ``u0002`` from the west to a goal north-east, ``u0003`` from the east to
    one south-west: the one lane between the two at rest (2.66 separations)
    is wide enough for one unit at a time, and each blocked by a unit at rest
    goes round it, into that lane, towards the other.
    """
    return Crowd(
        "two units crossing between two at rest",
        starts=[(0.0, 66.5), (0.0, -66.5), c_start, d_start],
        goals=[(0.0, 66.5), (0.0, -66.5), (154.0, 65.0), (-154.0, -65.0)],
        kinds=["manned", "unmanned", "unmanned", "unmanned"],
        threats={},
        limit_s=400.0,
    )


def jam() -> Crowd:
    """Unmanned ``u0001`` 55 m west of manned ``u0000`` (1.1 separations), two units at rest on their goals
    55 m east and west of the pair: ``u0000``'s way north-west meets ``u0001``'s north-east, so ``u0001``
    yields to it, and ``u0001``'s back-off west is into the disc of the unit at rest behind it (the head
    of the gaps crowd's jam at seed 4)."""
    return Crowd(
        "a unit yielding beside the one it yields to, between units at rest",
        starts=[(0.0, 0.0), (-55.0, 0.0), (55.0, 0.0), (-110.0, 0.0)],
        goals=[(-150.0, 1500.0), (400.0, 1500.0), (55.0, 0.0), (-110.0, 0.0)],
        kinds=["manned", "unmanned", "unmanned", "unmanned"],
        threats={},
        limit_s=400.0,
    )
