"""``pfp replay``: a record's inputs put again on a mission, and the planner's directions compared.

The inputs are what units and operators sent: unit states, goals, threats and
zones (and their DELETEs), and the units' liveliness tokens.  They go out in
recorded order, on the recorded clock divided by ``speed_up``, into the mission
given (the record's own by default), with two waits that keep a replay
faithful on a loaded machine:

* a goal, threat or zone is an acknowledged write (``wire.delivery``), and
  no state after it is sent before a planner has taken it (as in the live
  run, where the unit reported after the script's writes);
* a unit's next state waits (up to ``answer_wait_s``) for the planner's answer
  to its previous one (as ``pfp fleet``'s lockstep did);
* a state the live planner answered with its look-ahead landed (``deliberating``
  false) waits (up to ``landing_wait_s``) for the fresh planner's look-ahead
  to land too: deliberation runs beside the stream, so a replay that did not
  wait would see it land a few states earlier or later.

Every direction of the record that answered a state (``unit``, ``seq``) is
then compared with the first direction the planner gave for the same state:
the same status and the same vector (within ``ANGLE_TOL_DEG``).  A difference
names the unit, the state (its seq, position and time), both directions, and
the likely cause: the inputs that came just before it, or a look-ahead that
landed at a different moment (deliberation is asynchronous by design).
"""

from __future__ import annotations

import contextlib
import json
import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pfp_clients.record.mcapfile import Entry, Record
from pfp_service.errors import InputError
from pfp_service.wire import keys

__all__ = ["ANGLE_TOL_DEG", "Difference", "ReplayResult", "compare", "replay", "replay_inputs"]

ANGLE_TOL_DEG = 1e-3  # a direction's vector is the same when it turns less than this
_WRITES = {keys.KeyKind.UNIT_GOAL, keys.KeyKind.THREAT} | {
    k for k in keys.KeyKind if k.value == "zone"
}  # acknowledged writes


def _input_kinds() -> set[keys.KeyKind]:
    # states on any key a planner reads them from (D2's shard keys included, once they exist)
    return {k for k in keys.KeyKind if k.value.endswith("state")} | _WRITES


@dataclass(frozen=True)
class Answer:
    status: str
    vector: tuple[float, float]
    deliberating: bool
    reason: str


@dataclass(frozen=True)
class Difference:
    """One state the two runs answered differently."""

    unit: str
    seq: int
    t_s: float
    position: tuple[float, float] | None
    recorded: Answer
    replayed: Answer | None
    why: str

    def line(self) -> str:
        where = f"({self.position[0]:.2f}, {self.position[1]:.2f})" if self.position else "?"
        rec = f"{self.recorded.status} {_heading(self.recorded.vector):.1f} deg"
        if self.replayed is None:
            got = "no answer"
        else:
            got = f"{self.replayed.status} {_heading(self.replayed.vector):.1f} deg"
        return f"t={self.t_s:8.2f}s  {self.unit} seq {self.seq} at {where}: recorded {rec}, replayed {got}: {self.why}"


@dataclass
class ReplayResult:
    compared: int = 0
    same: int = 0
    differences: list[Difference] = field(default_factory=list)
    inputs_sent: int = 0
    replayed_answers: int = 0
    max_turn_deg: float = 0.0  # the largest angle between a recorded and a replayed vector
    status_differs: int = 0

    @property
    def ok(self) -> bool:
        return self.compared > 0 and not self.differences


def _heading(v: tuple[float, float]) -> float:
    return math.degrees(math.atan2(v[0], v[1])) % 360.0  # compass: 0 north, 90 east


def _answer(d: dict[str, Any]) -> Answer:
    vx, vy = d.get("vector", (0.0, 0.0))
    return Answer(
        str(d.get("status")), (float(vx), float(vy)), bool(d.get("deliberating")), str(d.get("reason", ""))
    )


def recorded_answers(rec: Record) -> dict[tuple[str, int], tuple[int, Answer]]:
    """The record's first direction for each (unit, seq), with its log time."""
    out: dict[tuple[str, int], tuple[int, Answer]] = {}
    for e in rec.entries:
        if e.data is None or "/direction" not in e.key:
            continue
        try:
            k = keys.parse(e.key)
            d = json.loads(e.data)
        except (InputError, ValueError):
            continue
        if k.kind is keys.KeyKind.UNIT_DIRECTION and isinstance(d.get("seq"), int):
            out.setdefault((k.id, d["seq"]), (e.t_ns, _answer(d)))
    return out


def _turn(a: Answer, b: Answer) -> float:
    """Degrees between the two vectors (180 when one is zero and the other not, 0 when both are)."""
    na, nb = math.hypot(*a.vector), math.hypot(*b.vector)
    if na == 0 or nb == 0:
        return 0.0 if na == nb else 180.0
    return abs((_heading(a.vector) - _heading(b.vector) + 180.0) % 360.0 - 180.0)


def _same(a: Answer, b: Answer) -> bool:
    return a.status == b.status and _turn(a, b) <= ANGLE_TOL_DEG


def _writes(rec: Record) -> tuple[list[int], list[Entry]]:
    """The record's goals, threats and zones (puts and deletes) in time order, and their times."""
    out = []
    for e in rec.entries:
        with contextlib.suppress(InputError):
            if keys.parse(e.key).kind in _WRITES:
                out.append(e)
    return [e.t_ns for e in out], out


def _cause(
    writes: tuple[list[int], list[Entry]], t_ns: int, a: Answer, b: Answer | None, landed: int | None
) -> str:
    import bisect

    if b is None:
        return "the fresh planner never answered this state"
    if a.deliberating != b.deliberating:
        return "the look-ahead landed at another moment (deliberation runs beside the stream)"
    if landed is not None:
        return (
            f"after the unit's look-ahead landed (seq {landed}): a route searched under a deadline "
            "may differ from run to run on a loaded machine"
        )
    i = bisect.bisect_right(writes[0], t_ns)
    if i > 0:
        last = writes[1][i - 1]
        what = "removed" if last.data is None else "put"
        ago = (t_ns - last.t_ns) / 1e9
        return f"the inputs in force differed: {last.key.split('/', 2)[-1]} was {what} {ago:.2f} s before"
    if a.status != b.status:
        return f"status {a.status} against {b.status}"
    return "the same inputs, another direction: the planner's settings differ (intensity, escape, step)"


def compare(
    rec: Record,
    replayed: dict[tuple[str, int], Answer],
    positions: dict[tuple[str, int], tuple[float, float]],
) -> ReplayResult:
    """Each recorded (unit, seq) answer against the replayed one."""
    out = ReplayResult()
    t0 = rec.entries[0].t_ns if rec.entries else 0
    writes = _writes(rec)
    deliberated: dict[str, int] = {}  # the unit's newest seq answered while its look-ahead ran
    for (unit, seq), (t_ns, a) in sorted(recorded_answers(rec).items(), key=lambda kv: kv[1][0]):
        out.compared += 1
        if a.deliberating:
            deliberated[unit] = seq
        b = replayed.get((unit, seq))
        if b is not None and _same(a, b):
            out.same += 1
            continue
        landed = deliberated[unit] + 1 if unit in deliberated and not a.deliberating else None
        why = _cause(writes, t_ns, a, b, landed)
        if b is not None:
            out.max_turn_deg = max(out.max_turn_deg, _turn(a, b))
            out.status_differs += a.status != b.status
        out.differences.append(
            Difference(unit, seq, (t_ns - t0) / 1e9, positions.get((unit, seq)), a, b, why)
        )
    out.replayed_answers = len(replayed)
    return out


def replay_inputs(rec: Record, mission: str) -> list[tuple[Entry, keys.Key, str]]:
    """The record's inputs, each with the key it is put on in ``mission``: only ever a key of ``mission``.

    Raises:
        InputError: at ``--mission``, a bad mission; naming the record's mission, when the record holds
            an input or a liveliness token of another mission (a replay retargets only its own).
    """
    m = keys.check_chunk(mission, "--mission")
    kinds = _input_kinds()
    head = f"{keys.PREFIX}/{rec.mission}/"
    out: list[tuple[Entry, keys.Key, str]] = []
    foreign: list[str] = []
    for e in rec.entries:
        try:
            k = keys.parse(e.key)
        except InputError:
            continue
        if k.kind not in kinds:
            continue
        if k.mission != rec.mission or not e.key.startswith(head):
            foreign.append(e.key)
            continue
        target = f"{keys.PREFIX}/{m}/" + e.key[len(head) :]
        if keys.parse(target).mission != m:  # pragma: no cover - the prefix swap keeps the layout
            foreign.append(e.key)
            continue
        out.append((e, k, target))
    for _t, akey, _up in rec.alive:
        with contextlib.suppress(InputError):
            if keys.parse(akey).mission != rec.mission:
                foreign.append(akey)
    if foreign:
        raise InputError(
            "record",
            f"{len(foreign)} inputs are on missions other than the record's own {rec.mission!r} "
            f"(the first: {foreign[0]}); pfp replay writes only to its mission ({m!r}) and refuses them",
        )
    return out


def replay(
    session: Any,
    rec: Record,
    mission: str,
    speed_up: float,
    stop: threading.Event,
    say: Callable[[str], None] = print,
    answer_wait_s: float = 2.0,
    settle_s: float = 3.0,
    landing_wait_s: float = 5.0,
) -> ReplayResult:
    """Put ``rec``'s inputs on ``mission`` and compare the answers (see the module docstring)."""
    import zenoh

    from pfp_service.wire import decode_direction
    from pfp_service.wire.delivery import Deliverer

    m = keys.check_chunk(mission, "--mission")
    inputs = replay_inputs(rec, m)
    answers: dict[tuple[str, int], Answer] = {}
    delib: dict[str, bool] = {}
    recorded = recorded_answers(rec)
    got: queue.Queue[tuple[str, int]] = queue.Queue()

    def on_direction(sample: zenoh.Sample) -> None:  # decode and enqueue
        with contextlib.suppress(InputError):
            d = decode_direction(sample.payload.to_bytes())
            delib[d.unit] = d.deliberating  # the newest word, pushes included
            if d.seq is not None:
                got.put((d.unit, d.seq))
                key = (d.unit, d.seq)
                if key not in answers:  # the first answer to a state; pushes that follow reuse its seq
                    answers[key] = Answer(
                        d.status.value, (d.vector[0], d.vector[1]), d.deliberating, d.reason
                    )

    sub = session.declare_subscriber(keys.unit_directions(m), on_direction)
    tokens: dict[str, Any] = {}
    last_seq: dict[str, int] = {}
    positions: dict[tuple[str, int], tuple[float, float]] = {}
    answered: set[tuple[str, int]] = set()
    writes = Deliverer(session, m, say)
    sent = 0
    say(f"replay: {len(inputs)} inputs of mission {rec.mission!r} onto {m!r}, x{speed_up:g}")
    t_first = inputs[0][0].t_ns if inputs else 0
    alive = sorted(rec.alive)
    ai = 0
    wall0 = time.monotonic()
    lag_s = 0.0  # time spent waiting on the planner: the replay's clock waits with it

    def drain() -> None:
        with contextlib.suppress(queue.Empty):
            while True:
                answered.add(got.get_nowait())

    try:
        for e, k, key in inputs:
            if stop.is_set():
                break
            due = wall0 + lag_s + (e.t_ns - t_first) / 1e9 / speed_up
            while (left := due - time.monotonic()) > 0 and not stop.is_set():
                time.sleep(min(left, 0.05))
            while ai < len(alive) and alive[ai][0] <= e.t_ns:  # the units' tokens, as they were
                _t, akey, up = alive[ai]
                ai += 1
                ak = keys.parse(akey)
                if ak.kind is not keys.KeyKind.ALIVE_UNIT or ak.mission != rec.mission:
                    continue
                if up and ak.id not in tokens:
                    tokens[ak.id] = session.liveliness().declare_token(keys.alive_unit(m, ak.id))
                elif not up and ak.id in tokens:
                    tokens.pop(ak.id).undeclare()
            if k.kind in _WRITES:
                if e.data is None:
                    writes.delete(key)
                else:
                    writes.put(key, e.data)
            else:
                if e.data is None:
                    continue
                try:
                    st = json.loads(e.data)
                except ValueError:
                    st = {}
                seq = st.get("seq") if isinstance(st, dict) else None
                prev = last_seq.get(k.id)
                t_wait = time.monotonic()
                if writes.pending():  # the writes before this state are in force first
                    writes.wait_delivered(10.0)
                if prev is not None:  # lockstep: the planner answered the previous state
                    limit = time.monotonic() + answer_wait_s
                    drain()
                    while (k.id, prev) not in answered and time.monotonic() < limit and not stop.is_set():
                        with contextlib.suppress(queue.Empty):
                            answered.add(got.get(timeout=0.02))
                mine = recorded.get((k.id, seq)) if isinstance(seq, int) else None
                if mine is not None and not mine[1].deliberating and delib.get(k.id):
                    # live, the unit's look-ahead had landed before this state: so it does here
                    limit = time.monotonic() + landing_wait_s
                    while delib.get(k.id) and time.monotonic() < limit and not stop.is_set():
                        time.sleep(0.005)
                lag_s += time.monotonic() - t_wait
                if isinstance(seq, int):
                    last_seq[k.id] = seq
                    pos = st.get("position")
                    if isinstance(pos, list) and len(pos) >= 2:
                        positions[(k.id, seq)] = (float(pos[0]), float(pos[1]))
                session.put(key, e.data, encoding=zenoh.Encoding.APPLICATION_JSON)
            sent += 1
        # the last answers
        end = time.monotonic() + settle_s
        want = set(recorded)
        while time.monotonic() < end and not stop.is_set() and not want <= set(answers):
            time.sleep(0.05)
    finally:
        writes.close()
        for t in tokens.values():
            with contextlib.suppress(Exception):
                t.undeclare()
        with contextlib.suppress(Exception):
            sub.undeclare()
    result = compare(rec, dict(answers), positions)
    result.inputs_sent = sent
    return result


def result_lines(r: ReplayResult, limit: int = 20) -> list[str]:
    """The comparison in words: the counts, then the first ``limit`` differences."""
    lines = [
        f"replay: {r.inputs_sent} inputs sent; {r.compared} recorded directions compared, "
        f"{r.same} the same, {len(r.differences)} differ"
        + (
            f" (by at most {r.max_turn_deg:.3g} deg; {r.status_differs} in status; "
            f"{sum(d.replayed is None for d in r.differences)} unanswered)"
            if r.differences
            else ""
        )
    ]
    for d in r.differences[:limit]:
        lines.append("  " + d.line())
    if len(r.differences) > limit:
        lines.append(f"  ... and {len(r.differences) - limit} more")
    if r.compared == 0:
        lines.append("replay: the record holds no direction answering a state: nothing to compare")
    else:
        lines.append("replay: the same directions" if r.ok else "replay: DIFFERENT directions (see above)")
    return lines
