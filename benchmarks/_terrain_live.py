"""The live rows of ``pfp bench terrain``: a threat put over terrain ahead of 1,000 live units, over Zenoh.

``pfp serve --terrain`` runs in its own process on a loopback router over
the bench's grid (the Jacksboro DEM at ``--cell`` metres, 1,000 x 1,000
cells) and this process acts as 1,000 units standing round its centre,
each with a goal a short way off (``benchmarks._load.LoadGen``).

* **The wave.**  The units go quiet; a threat reaching about 5 km is put
  at the centre.  Its window is computed off the planner's loop
  (``node.terrain.Sights``), and every direction since is a push: the
  time until every unit its replan names has one (target: 100 ms), and,
  by an exact ray over each unit's corridor (``exact_lowest_visible_height``,
  not the planner's sweep), how many of those the threat sees, how many
  it cannot see at all (re-directed in vain: should be none) and how many
  it sees that were not re-directed.
* **Bystanders.**  The units report at ``LIVE_HZ`` again, in windows of
  ``WINDOW_S``, alternately plain (A) and with the threat moved a few
  metres half-way through (B: a fresh window, a fresh sweep on the
  planner's sight thread); the p99 of the bystanders' state-to-direction
  latency (the units the wave did not reach and no ray sees) in B against
  A, same run (target: within 20 %), pooled over ``ROUNDS`` pairs.  With two
  pairs or more, the A windows are also split in two (odd against even) and
  compared alike: the noise floor, what the ratio moves with no threat moved
  at all.  A p99 of a few milliseconds is the 1 % tail of a 2-core machine's
  scheduling: A's own p99 moved from 4.0 to 6.5 ms between runs of one tree
  with two pairs (2026-12-07), so the default pools six.
* **Since the move.**  The B windows' bystander answers by the time their
  state was sent after the threat moved (``SINCE_MOVE_MS``: before it, the
  window's sweep, the wave, the deliberation that follows): how many, their
  p50 and p99, and the fraction slower than A's p99 and than the target's
  line (1.2x A's p99).  Where B's tail comes from, in the bench's own output.
* **What the row can settle.**  With the A windows apart by more than the
  20 % the row tests (``unresolved``: 1.05-3.83x in one afternoon's runs,
  the generator's own collector's pauses, since fixed: BENCHMARKS.md "The
  load generator's own pauses"), or with no floor (one pair), a ratio within
  20 % is noise: ``--check`` counts it as not met, and says why.
"""

from __future__ import annotations

import bisect
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

REDIRECT_TARGET_MS = 100.0
BYSTANDER_TARGET = 1.20  # p99 with a threat put against without, same run
UNITS = 1_000
LIVE_HZ = 1.0
WINDOW_S = 3.0
ROUNDS = 6  # A/B pairs, alternating (``pfp bench terrain --rounds``)
SIGMA_M = 1_500.0  # the threat's reach: its term is above 1e-9 of its peak to about 6.4 sigma
GOAL_M = 250.0
# the edges of ``since_move``'s bins, ms after the move (the first bin: the window before it)
SINCE_MOVE_MS = (0.0, 50.0, 110.0, 300.0, 600.0, 1_000.0)  # the move is 1.5 s before the window ends


def live(grid: Any, tif: Path, seed: int = 32, rounds: int = ROUNDS) -> dict[str, Any]:
    """The wave and the bystanders' A/B, against ``pfp serve --terrain tif`` (the same grid as ``grid``)."""
    from benchmarks._load import MISSION, LoadGen, start_server
    from benchmarks._phases import deliberations_landed, latency, register
    from pfp_service.wire import Goal, ThreatUpdate, keys

    rng = np.random.default_rng(seed)
    r = rng.uniform(300.0, 4_000.0, UNITS + 1)
    a = rng.uniform(0.0, 2 * math.pi, UNITS + 1)
    starts = np.column_stack([r * np.sin(a), r * np.cos(a)])
    b = rng.uniform(0.0, 2 * math.pi, UNITS + 1)
    goals = starts + GOAL_M * np.column_stack([np.sin(b), np.cos(b)])
    sees = _seen_by_ray(grid, starts, goals)
    srv = start_server("planner", stale_s=600.0, extra=("--terrain", str(tif)))
    out: dict[str, Any] = {"units": UNITS, "seen_by_exact_ray": int(sees[:UNITS].sum())}
    try:
        g = _connected(lambda: LoadGen(srv.endpoint, [(float(x), float(y)) for x, y in starts], 0.0), srv)
        try:
            g.wait_ready(300.0)
            for i in range(UNITS + 1):
                g.put_json(
                    keys.unit_goal(MISSION, g.ids[i]), Goal(position=(float(goals[i, 0]), float(goals[i, 1])))
                )
            out["registered"] = register(g, UNITS)
            g.pace((UNITS + 1) * LIVE_HZ, 3.0, list(range(UNITS + 1)))
            out["deliberations_before"] = deliberations_landed(g, 60.0)
            g.settle(0.5, 5.0)
            out["wave"] = _wave(
                g, sees, ThreatUpdate(position=(0.0, 0.0), sigma_range=SIGMA_M, sigma_lateral=SIGMA_M)
            )
            hidden = {g.ids[i] for i in range(UNITS) if not sees[i]} - set(out["wave"]["redirected_ids"])
            del out["wave"]["redirected_ids"]
            deliberations_landed(g, 60.0)
            out["bystanders"] = _ab(g, hidden, latency, rounds)
        finally:
            g.close()
    finally:
        out["server"] = srv.stop()
    return out


def _connected(make: Any, srv: Any, cap_s: float = 300.0) -> Any:
    """The load generator (units standing still) once the planner listens: it loads the DEM first."""
    t0 = time.perf_counter()
    while True:
        try:
            return make()
        except Exception:
            if time.perf_counter() - t0 > cap_s or srv.proc.poll() is not None:
                raise
            time.sleep(1.0)


def _wave(g: Any, sees: np.ndarray, threat: Any) -> dict[str, Any]:
    from benchmarks._load import MISSION
    from pfp_service.wire import keys

    mark, ev_mark = len(g.recv), len(g.events)
    t_put = time.perf_counter()
    g.put_json(keys.threat(MISSION, "ridge"), threat)
    affected: int | None = None
    first: dict[str, float] = {}
    while time.perf_counter() < t_put + 3.0:
        time.sleep(0.005)
        for rc in g.recv[mark:]:
            first.setdefault(rc.unit, rc.t)
        mark = len(g.recv)
        for _t, kind, doc in g.events[ev_mark:]:
            if kind == "replan" and affected is None:
                affected = len(doc.get("units", [])) + int(doc.get("more_units", 0))
        if affected is not None and len(first) >= affected:
            break
    g.settle(0.6, 3.0)
    for rc in g.recv[mark:]:
        if rc.t >= t_put:
            first.setdefault(rc.unit, rc.t)
    replans = [doc for _t, kind, doc in g.events[ev_mark:] if kind == "replan"]
    told = sorted(t - t_put for u, t in first.items() if u != g.ids[-1])
    idx = [g.index[u] for u in first if u != g.ids[-1]]
    complete = affected is not None and len(first) >= affected
    return {
        "affected": affected,
        "replans": len(replans),
        "redirected": len(told),
        "all_redirected_ms": 1e3 * told[-1] if told and complete else None,
        "redirected_p50_ms": 1e3 * told[len(told) // 2] if told else None,
        "redirected_unseen_by_ray": int(sum(1 for i in idx if not sees[i])),
        "seen_by_ray_not_redirected": int(sees[: len(sees) - 1].sum()) - int(sum(1 for i in idx if sees[i])),
        "redirected_ids": sorted(first),
    }


def _ab(g: Any, bystanders: set[str], latency: Any, rounds: int = ROUNDS) -> dict[str, Any]:
    """Alternate windows without (A) and with (B) a threat moved half-way through; the bystanders' p99 of each,
    and of the A windows split in two (``A_halves``: the noise floor, when there are two A windows or more)."""
    from benchmarks._load import MISSION
    from pfp_service.wire import ThreatUpdate, keys

    windows: list[tuple[str, list[int]]] = []
    moves: dict[int, float] = {}  # B window -> when its threat was moved (``perf_counter``, as ``g.sent``)
    everyone = list(range(UNITS + 1))
    for k in range(2 * rounds):
        phase = "AB"[k % 2]
        moved = ThreatUpdate(position=(5.0 * (k + 1), 0.0), sigma_range=SIGMA_M, sigma_lateral=SIGMA_M)

        def put_once(done: float, phase: str = phase, moved: Any = moved, k: int = k) -> None:
            if phase == "B" and done >= 0.5 and k not in moves:  # once, half-way through
                moves[k] = time.perf_counter()
                g.put_json(keys.threat(MISSION, "ridge"), moved)

        first, end, _spent = g.pace((UNITS + 1) * LIVE_HZ, WINDOW_S, everyone, tick=put_once)
        windows.append((phase, [s for s in range(first, end) if g.seq_unit[s] in bystanders]))
        g.settle(0.5, 3.0)

    def pooled(keep: Any) -> dict[str, Any]:
        got: dict[str, Any] = latency(
            g, [s for i, (ph, seqs) in enumerate(windows) if keep(i, ph) for s in seqs], g.recv
        )
        return got

    a, b = pooled(lambda _i, ph: ph == "A"), pooled(lambda _i, ph: ph == "B")
    out = {"bystanders": len(bystanders), "rounds": rounds, "A": a, "B": b, "p99_ratio": _ratio(b, a)}
    if rounds >= 2:  # A windows 1, 3, 5 ... against 2, 4, 6 ...: nothing differs but the machine's noise
        odd, even = (
            pooled(lambda i, ph: ph == "A" and i % 4 == 0),
            pooled(lambda i, ph: ph == "A" and i % 4 == 2),
        )
        out["A_halves_p99_ms"] = [odd["p99_ms"], even["p99_ms"]]
        out["A_halves_p99_ratio"] = _ratio(even, odd)
    if a["p99_ms"] is not None:
        out["since_move"] = since_move(g, windows, moves, a["p99_ms"])
    out["unresolved"] = unresolved(out)
    return out


def unresolved(by: dict[str, Any]) -> str | None:
    """Why the bystanders' A/B cannot settle the target, or ``None`` when it can: a ratio within 20 %
    means nothing when plain windows alone differ by more (the noise floor, A against A, either way
    round), nor when there is no floor to compare it with (one pair).  Each half of the A windows has
    half the samples of the A/B, so the floor is if anything wider than the A/B's own noise: the test
    errs towards "not met"."""
    floor = by.get("A_halves_p99_ratio")
    if floor is None or not floor > 0.0 or not math.isfinite(floor):
        return "no noise floor to judge it against (one window pair, or a half without answers)"
    spread = max(floor, 1.0 / floor)
    if spread > BYSTANDER_TARGET:
        return f"plain against plain already differs by {spread:.2f}x"
    return None


def since_move(
    g: Any, windows: list[tuple[str, list[int]]], moves: dict[int, float], a_p99_ms: float
) -> list[dict[str, Any]]:
    """The B windows' answered bystander states in ``SINCE_MOVE_MS``'s bins of the time each was sent after
    its window's move: count, p50, p99, and the fractions slower than ``a_p99_ms`` and than 1.2x it."""
    first: dict[int, float] = {}
    for rc in g.recv:
        first.setdefault(rc.seq, rc.t)
    edges = [-math.inf, *SINCE_MOVE_MS, math.inf]
    bins: list[list[float]] = [[] for _ in range(len(edges) - 1)]
    for k, (phase, seqs) in enumerate(windows):
        if phase != "B" or k not in moves:
            continue
        for s in seqs:
            if s in first:  # bin 0: sent before the move; bin i: at least SINCE_MOVE_MS[i - 1] after it
                i = bisect.bisect_right(SINCE_MOVE_MS, 1e3 * (g.sent[s] - moves[k]))
                bins[i].append(1e3 * (first[s] - g.sent[s]))
    out = []
    for i, ms in enumerate(bins):
        a = np.asarray(ms)
        out.append(
            {
                "from_ms": None if i == 0 else edges[i],
                "to_ms": None if i == len(bins) - 1 else edges[i + 1],
                "answers": len(ms),
                "p50_ms": float(np.percentile(a, 50)) if len(ms) else None,
                "p99_ms": float(np.percentile(a, 99)) if len(ms) else None,
                "over_A_p99": float((a > a_p99_ms).mean()) if len(ms) else None,
                "over_target": float((a > BYSTANDER_TARGET * a_p99_ms).mean()) if len(ms) else None,
            }
        )
    return out


def _ratio(b: dict[str, Any], a: dict[str, Any]) -> float | None:
    return b["p99_ms"] / a["p99_ms"] if a["p99_ms"] and b["p99_ms"] is not None else None


def _seen_by_ray(grid: Any, starts: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """Whether a threat at (0, 0), 2 m up, sees each unit somewhere along its corridor (exact rays, foot height)."""
    from pfp_service.core.mobility import CLASSES
    from pfp_service.terrain.viewshed import exact_lowest_visible_height

    c = grid.cell_m
    obs = (round(-grid.y0_m / c), round(-grid.x0_m / c))
    t = np.linspace(0.0, 1.0, 11)[None, :, None]
    pts = starts[:, None, :] + t * (goals - starts)[:, None, :]
    cols = np.clip(np.rint((pts[..., 0] - grid.x0_m) / c).astype(int), 0, grid.shape[1] - 1)
    rows = np.clip(np.rint((pts[..., 1] - grid.y0_m) / c).astype(int), 0, grid.shape[0] - 1)
    cells = np.column_stack([rows.ravel(), cols.ravel()])
    low = exact_lowest_visible_height(grid.z, obs, 2.0, cells, c, c).reshape(rows.shape)
    return np.asarray((low <= CLASSES["foot"].height_m).any(axis=1))


def print_live(out: dict[str, Any]) -> None:
    if "not_run" in out:
        print(f"  live (1,000 units, Zenoh)   not run: {out['not_run']}")
        return
    w, by = out["wave"], out["bystanders"]
    print(
        f"  live wave (1,000 units)     {w['redirected']} re-directed of {w['affected']} its replan named,"
        f" all within {_ms(w['all_redirected_ms'])} (p50 {_ms(w['redirected_p50_ms'])});"
        f" exact rays: {out['seen_by_exact_ray']} seen, {w['redirected_unseen_by_ray']} re-directed unseen,"
        f" {w['seen_by_ray_not_redirected']} seen not re-directed"
    )
    floor = by.get("A_halves_p99_ratio")
    print(
        f"  live bystanders ({by['bystanders']})       p99 {_ms(by['A']['p99_ms'])} plain,"
        f" {_ms(by['B']['p99_ms'])} with a threat moved ({_x(by['p99_ratio'])}; {by.get('rounds', ROUNDS)} pairs"
        + (f", plain against plain {_x(floor)})" if floor is not None else ")")
    )
    if (why := unresolved(by)) is not None:
        print(f"    inconclusive, the row cannot settle the 20 %: {why}")
    rows = by.get("since_move") or []
    if rows:
        print("    B's answers by when they were sent: over 1.2x plain's p99 (of how many)")
        print("      " + ", ".join(f"{_span(r)} {_pct(r['over_target'])} ({r['answers']})" for r in rows))


def _span(r: dict[str, Any]) -> str:
    if r["from_ms"] is None:
        return "before the move"
    return f"{r['from_ms']:.0f}+ ms" if r["to_ms"] is None else f"{r['from_ms']:.0f}-{r['to_ms']:.0f} ms"


def _pct(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:.1f} %"


def _ms(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.0f} ms"


def _x(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}x"


def met(out: dict[str, Any]) -> tuple[bool, bool]:
    """(every unit it sees re-directed within the target, bystanders' p99 within the target)."""
    if "not_run" in out:
        return False, False
    w, by = out["wave"], out["bystanders"]
    wave_ok = w["all_redirected_ms"] is not None and w["all_redirected_ms"] <= REDIRECT_TARGET_MS
    within = by["p99_ratio"] is not None and by["p99_ratio"] <= BYSTANDER_TARGET
    return wave_ok, within and unresolved(by) is None  # a ratio the noise floor cannot resolve is not met
