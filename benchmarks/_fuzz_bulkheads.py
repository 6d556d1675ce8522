"""The bulkhead phases of ``pfp bench fuzz``: poison goals beside innocent units, and preview bombs.

Each phase takes an open session to a running planner and returns its figures
and verdicts; ``bench.fuzz`` runs them after the wire fuzz.  Valid JSON, every
one: what these find is not a decoder's gap but one input costing others.
"""

from __future__ import annotations

import json
import math
import random
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from benchmarks._procs import tree_pss_mb

__all__ = [
    "BOMB_GROWTH_MB",
    "BOMB_PLAIN_S",
    "BOMB_SETTLE_S",
    "INNOCENT_SHARE",
    "MISSION",
    "POISON_GOALS",
    "PREVIEW_BOMBS",
    "is_timeout",
    "poison_goals",
    "preview_bombs",
]

MISSION = "fuzz"


# -- poison goals: valid JSON whose numbers once broke the planner (issue 21) ------------------
# The bad unit reports from [0, 0]; each goal is sent with every one of its reports.  The
# decoders refuse the subnormal step, tolerance and delta (>= 1 mm, >= 1e-9: constraints);
# the offsets and the goal on the unit have arrived.  Neither may cost another unit a direction.
POISON_GOALS: dict[str, dict[str, Any] | None] = {
    "none": None,  # the same run's baseline: the bad unit reports and sends no goal
    "subnormal_offset": {"position": [5e-324, 5e-324]},
    "subnormal_step": {"position": [10.0, 10.0], "step": 5e-324},
    "subnormal_tolerance": {"position": [10.0, 10.0], "tolerance": 5e-324},
    "subnormal_delta": {"position": [10.0, 10.0], "delta": 5e-324},
    "goal_on_unit": {"position": [0.0, 0.0]},
    "offset_1e-300": {"position": [1e-300, 1e-300]},
}
INNOCENTS = 20
POISON_S = 2.0  # seconds of each poison, at POISON_HZ
POISON_HZ = 10.0
INNOCENT_SHARE = 0.95  # of the innocent units' reports answered, to pass


def poison_goals(session: Any, say: Callable[[str], None] = print) -> dict[str, Any]:
    """Each of ``POISON_GOALS`` from a bad unit while ``INNOCENTS`` units report in the same ticks.

    A report counts as answered when a direction answers it or the unit's
    next report (directions are latest-wins: a planner a tick behind answers
    the newer one); ``none`` is the same run's baseline, with no poison.

    Returns:
        ``innocent_share`` over the poisons, ``baseline_share`` without one,
        and per poison its share and what the bad unit was told.
    """
    import threading

    import zenoh

    from pfp_service.wire import decode_direction, keys

    enc = zenoh.Encoding.APPLICATION_JSON
    block = zenoh.CongestionControl.BLOCK
    lock = threading.Lock()
    got: set[tuple[str, int]] = set()
    bad_told: Counter[str] = Counter()

    def on_direction(sample: Any) -> None:
        try:
            d = decode_direction(sample.payload.to_bytes())
        except Exception:
            return
        with lock:
            if d.unit == "poisoner":
                bad_told[d.status.value] += 1
            elif d.seq is not None:
                got.add((d.unit, d.seq))

    sub = session.declare_subscriber(keys.unit_directions(MISSION), on_direction)
    names = [f"innocent{i}" for i in range(INNOCENTS)]
    per: dict[str, Any] = {}
    seq = 0
    try:
        for name in names:
            goal = json.dumps({"position": [10.0 + names.index(name) % 5, 12.0]}).encode()
            session.put(keys.unit_goal(MISSION, name), goal, encoding=enc, congestion_control=block)
        for poison, body in POISON_GOALS.items():
            session.delete(keys.unit_goal(MISSION, "poisoner"))  # what it is told is this poison's alone
            time.sleep(0.2)
            with lock:
                bad_told.clear()
            first = seq + 1
            t0 = time.monotonic()
            for tick in range(int(POISON_S * POISON_HZ)):
                seq += 1
                bad_state = json.dumps({"position": [0.0, 0.0], "seq": seq}).encode()
                session.put(
                    keys.unit_state(MISSION, "poisoner"), bad_state, encoding=enc, congestion_control=block
                )
                if body is not None:
                    goal = json.dumps(body).encode()
                    session.put(
                        keys.unit_goal(MISSION, "poisoner"), goal, encoding=enc, congestion_control=block
                    )
                for i, name in enumerate(names):
                    state = json.dumps({"position": [float(i % 5), -3.0 - i // 5], "seq": seq}).encode()
                    session.put(keys.unit_state(MISSION, name), state, encoding=enc, congestion_control=block)
                time.sleep(max(t0 + (tick + 1) / POISON_HZ - time.monotonic(), 0.0))
            time.sleep(0.5)  # the last tick's directions
            with lock:
                answered = sum(
                    (n, k) in got or (n, k + 1) in got for n in names for k in range(first, seq + 1)
                )
                told = dict(bad_told)
            sent = len(names) * (seq + 1 - first)
            per[poison] = {"innocent_share": round(answered / sent, 4), "sent": sent, "bad_unit_told": told}
            say(
                f"  poison goal {poison}: innocent units answered {answered}/{sent}; the bad unit told {told}"
            )
    finally:
        sub.undeclare()
        for name in [*names, "poisoner"]:
            session.delete(keys.unit_goal(MISSION, name))
    poisoned = [p for name, p in per.items() if POISON_GOALS[name] is not None]
    sent_all = sum(p["sent"] for p in poisoned)
    answered_all = sum(round(p["innocent_share"] * p["sent"]) for p in poisoned)
    return {
        "innocent_share": round(answered_all / sent_all, 4) if sent_all else 0.0,
        "baseline_share": per["none"]["innocent_share"],
        "by_poison": per,
    }


# -- preview bombs ----------------------------------------------------------------------
def _wide(n: int, sigma_m: float, spread_m: float = 50.0, seed: int = 5) -> list[dict[str, Any]]:
    rng = random.Random(seed)
    return [
        {
            "id": f"b{i}",
            "position": [rng.uniform(-spread_m, spread_m), rng.uniform(-spread_m, spread_m)],
            "sigma_range": sigma_m if i % 2 else 5.0,
            "sigma_lateral": sigma_m if i % 2 else 3.0,
        }
        for i in range(n)
    ]


def _ring(n: int, radius_m: float) -> list[dict[str, Any]]:
    step = 2 * math.pi / n
    return [
        {
            "id": f"r{i}",
            "position": [radius_m * math.cos(i * step), radius_m * math.sin(i * step)],
            "sigma_range": 1.0,
            "sigma_lateral": 1.0,
        }
        for i in range(n)
    ]


# Previews built to exhaust the host: each must be answered (a plan or an error that decodes) within
# BOMB_ANSWER_S, and afterwards the planner's process tree must be back within BOMB_GROWTH_MB.
PREVIEW_BOMBS: dict[str, Callable[[], dict[str, Any]]] = {
    "goal 1e9 m away at 1 mm, 256 what-ifs half a megametre wide": lambda: {
        "start": [-900, -900],
        "goal": [1e9, 1e9],
        "step": 1e-3,
        "max_iter": 10_000_000,
        "threats": _wide(256, 1e6),
    },
    "64 what-ifs 1e6 m wide": lambda: {"start": [0, 0], "goal": [500, 500], "threats": _wide(64, 1e6)},
    "65 what-ifs": lambda: {"start": [0, 0], "goal": [50, 50], "threats": _wide(65, 1.0)},
    "190 m at 1 mm (just under the step cap)": lambda: {
        "start": [0, 0],
        "goal": [134, 134],
        "step": 1e-3,
        "max_iter": 10_000_000,
    },
    "the start ringed by 64 what-ifs at 1 cm steps": lambda: {
        "start": [0, 0],
        "goal": [100, 100],
        "step": 0.01,
        "threats": _ring(64, 4.0),
    },
}
BOMB_COPIES = 3  # of each bomb, at once
BOMB_ANSWER_S = 5.0
BOMB_SETTLE_S = 8.0  # the process tree is measured this long after the last answer
BOMB_GROWTH_MB = 400.0
BOMB_PLAIN_S = 3.0  # then a plain preview gets a plan within this


def preview_bombs(session: Any, pid: int, say: Callable[[str], None] = print) -> dict[str, Any]:
    """Each of ``PREVIEW_BOMBS``, ``BOMB_COPIES`` at once: answers, the tree's memory after, a plain preview."""
    from pfp_service.wire import keys

    errors: Counter[str] = Counter()

    def ask(body: bytes) -> tuple[float, str]:
        t0 = time.monotonic()
        replies = list(session.get(keys.preview(MISSION, "bomber"), payload=body, timeout=BOMB_ANSWER_S + 5))
        took = time.monotonic() - t0
        if not replies or is_timeout(replies[0]):
            return took, "unanswered"
        if replies[0].ok is None:
            errors[replies[0].err.payload.to_bytes().decode(errors="replace")[:100]] += 1
        return took, "plan" if replies[0].ok is not None else "error"

    before = tree_pss_mb(pid)
    per: dict[str, Any] = {}
    for name, make in PREVIEW_BOMBS.items():
        body = json.dumps(make()).encode()
        out: list[tuple[float, str]] = []
        threads = [threading.Thread(target=lambda: out.append(ask(body))) for _ in range(BOMB_COPIES)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        per[name] = {"answers": sorted(k for _, k in out), "slowest_s": round(max(s for s, _ in out), 3)}
        say(f"  preview bomb {name}: {per[name]['answers']} in at most {per[name]['slowest_s']} s")
    time.sleep(BOMB_SETTLE_S)
    after = tree_pss_mb(pid)
    plain = ask(json.dumps({"start": [0, 0], "goal": [10, 10]}).encode())
    say(
        f"  preview bombs: tree PSS {before:.0f} -> {after:.0f} MB; a plain preview then: {plain[1]} in {plain[0]:.2f} s"
    )
    return {
        "by_bomb": per,
        "answered_in_time": all(
            len(b["answers"]) == BOMB_COPIES
            and "unanswered" not in b["answers"]
            and b["slowest_s"] <= BOMB_ANSWER_S
            for b in per.values()
        ),
        "pss_mb_before": round(before, 1),
        "pss_mb_after": round(after, 1),
        "plain_after": {"kind": plain[1], "s": round(plain[0], 3)},
        "errors": dict(errors),
    }


def is_timeout(rep: Any) -> bool:
    """A Zenoh reply that is the query's own timeout, not an answer."""
    return rep.err is not None and rep.err.payload.to_bytes() == b"Timeout"
