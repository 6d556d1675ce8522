"""What a record missed of the planners' outputs, counted against their own ``msgs_out``.

A subscriber cannot see a message that never reached it, so the recorder asks
every planner of the mission for its status (``msgs_out``: directions, missions
and events it published) once its subscriptions are in place and again when it
stops, and counts the planner outputs it recorded between the two answers by
their log times (the router's timestamps).  The status answers take a round
trip each, so an output logged while a question was out may lie on either side
of its answer: the record says how many it missed at least (every recorded
output in the wider window counted) and at most (only those certainly inside).
On one machine the bounds are a few messages apart; across machines the
recorder's clock and the router's differ by their skew too.

Sans-I/O: ``Coverage`` is fed the answers and the recorded samples' kinds and
times, and says what it found; the recorder does the asking.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["PLANNER_OUT", "Counted", "Coverage", "describe", "describe_gaps", "seq_gaps"]

# the key kinds a planner's msgs_out counts (keys.KeyKind values)
PLANNER_OUT = frozenset({"unit_direction", "unit_mission", "event"})


@dataclass(frozen=True)
class Counted:
    """The planners' answer to a status question: ``msgs_out`` per (planner, session), and when it was asked."""

    out: dict[tuple[str, str], int]
    asked_ns: int
    answered_ns: int


@dataclass
class Coverage:
    """Planner outputs recorded in the windows around two status answers (see the module doc)."""

    first: Counted | None = None
    last: Counted | None = None
    _edges: list[int] = field(default_factory=list)
    _buckets: list[int] = field(default_factory=lambda: [0] * 5)

    def begin(self, answer: Counted) -> None:
        """The first answer, asked once the subscriptions are in place and before any sample is counted."""
        self.first = answer
        self._edges = [answer.asked_ns, answer.answered_ns]

    def end(self, answer: Counted) -> None:
        """The last answer, asked once the recording stops; samples still arriving are counted after it."""
        self.last = answer
        if self.first is not None:
            self._edges = [*self._edges[:2], answer.asked_ns, answer.answered_ns]

    def seen(self, kind: str, t_ns: int) -> None:
        """A recorded sample of key kind ``kind`` logged at ``t_ns``."""
        if kind in PLANNER_OUT and self._edges:
            self._buckets[bisect.bisect_right(self._edges, t_ns)] += 1

    def result(self) -> dict[str, Any]:
        """The verdict, as the record's ``pfp.coverage`` metadata holds it (every value a string there)."""
        if self.first is None or self.last is None or not self.first.out or not self.last.out:
            return {"counted": False, "why": "no planner answered its status at the start and at the end"}
        if set(self.first.out) != set(self.last.out):
            return {
                "counted": False,
                "why": "the planners changed during the recording (their counters start again)",
            }
        published = sum(self.last.out[p] - self.first.out[p] for p in self.first.out)
        b = self._buckets
        inside, wide = b[2], b[1] + b[2] + b[3]
        return {
            "counted": True,
            "planners": len(self.first.out),
            "published": published,
            "recorded": inside,
            "recorded_at_the_edges": wide - inside,
            "missed_at_least": max(0, published - wide),
            "missed_at_most": max(0, published - inside),
            "from_ns": self.first.answered_ns,
            "to_ns": self.last.asked_ns,
        }


def describe(cov: dict[str, Any]) -> str:
    """One line for people: what a record's coverage says."""
    if not cov.get("counted"):
        return f"planner outputs not counted: {cov.get('why', 'unknown')}"
    lo, hi = int(cov["missed_at_least"]), int(cov["missed_at_most"])
    missed = "none missed" if hi == 0 else (f"{lo:,} missed" if lo == hi else f"{lo:,} to {hi:,} missed")
    return (
        f"planner outputs: {int(cov['published']):,} published by {int(cov['planners'])} planner(s) "
        f"while recording, {int(cov['recorded']):,} recorded (+{int(cov['recorded_at_the_edges'])} "
        f"at the edges): {missed}"
    )


def seq_gaps(seqs: Sequence[int]) -> int | None:
    """How many of a unit's states are missing between its first and last recorded ``seq``.

    ``None`` when its seq does not count one by one (most steps other than 1: a load generator's
    shared counter, a bridge's own numbering), so that gaps say nothing.  A unit that restarted
    (its seq fell) is counted from the restart.
    """
    run: list[int] = []
    missing, steps, ones = 0, 0, 0
    for s in seqs:
        if run and s < run[-1]:  # restarted: count the run so far, then the new one
            missing += run[-1] - run[0] + 1 - len(set(run))
            run = []
        if run and s != run[-1]:
            steps += 1
            ones += s - run[-1] == 1
        run.append(s)
    if run:
        missing += run[-1] - run[0] + 1 - len(set(run))
    if steps and ones * 2 < steps:
        return None
    return missing


def describe_gaps(gaps: dict[str, int | None], shown: int = 8) -> str:
    """One line for people: the states missing by their seq, per unit (natural order given)."""
    counted = {u: n for u, n in gaps.items() if n is not None}
    if not counted:
        return "states: no unit counts its seq one by one: gaps not counted"
    short = {u: n for u, n in counted.items() if n}
    if not short:
        return f"states: none missing by their seq ({len(counted)} units)"
    listed = ", ".join(f"{u}: {n}" for u, n in list(short.items())[:shown])
    more = f", and {len(short) - shown} more units" if len(short) > shown else ""
    return f"states: {sum(short.values())} missing by their seq ({listed}{more})"
