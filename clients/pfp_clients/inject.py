"""``pfp inject``: play a contingency script against a live planner and judge its expectations.

The script (``pfp_clients.script``) is validated whole before the session
opens.  Its clock is simulated seconds, ``speed_up`` times the wall clock.
While it runs it follows every unit's state (for ``when`` triggers and
clearance), every direction's status and ``event/arrived`` (for arrival), and
prints each action with the time it fired.  It stops when the timeline is done
and every unit named by an expectation has arrived (or its deadline passed),
or at ``duration_s``.  Exit code 0 iff every expectation held and every
timeline entry fired.
"""

from __future__ import annotations

import contextlib
import math
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec

from pfp_clients.expectations import Fired, InjectReport, ZoneVersion, judge
from pfp_clients.frames import learn_planner_origin, planner_origin, reframe
from pfp_clients.script import (
    AddTeam,
    AddThreat,
    AddZone,
    CancelGoal,
    MoveThreat,
    RemoveTeam,
    RemoveThreat,
    RemoveZone,
    Script,
    SetGoal,
    Step,
    Wait,
    team_members,
)
from pfp_clients.watch import Watch
from pfp_service.coords import Coords
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import (
    ArrivedEvent,
    decode_direction,
    decode_event,
    decode_unit_state,
    encode,
    keys,
)
from pfp_service.world import translate

__all__ = [
    "main",
    "report_lines",
    "run_inject",
    "script_in_planner_frame",
]


def _settled(script: Script, watch: Watch, t_s: float) -> bool:
    teams = team_members(script)
    for e in script.expect:
        units = teams.get(e.team, ()) if e.team is not None else (e.unit,)
        if all(u in watch.arrived_at_s for u in units):
            continue
        if e.arrives_within_s is not None and t_s > e.arrives_within_s:
            continue
        return False
    return True


class _Runner:
    """The script's state machine; the Zenoh parts are the two callables it is given."""

    def __init__(
        self,
        script: Script,
        session: Any,
        mission: str,
        say: Callable[[str], None],
        coords: Coords | None = None,
    ) -> None:
        from pfp_service.wire.delivery import Deliverer

        self.coords = coords or Coords()
        self.show = self.coords.point if self.coords.geodetic else None  # metres: as the script wrote them
        self.script = script
        self.s = Deliverer(session, mission, say)  # goals and threats reach a planner that starts later
        self.m = mission
        self.say = say
        self.watch = Watch()
        self.index = 0
        self.wait_until: float | None = None
        self.fired: list[Fired] = []
        self.zones: list[ZoneVersion] = []

    def zone_put(self, step: AddZone, t_s: float) -> None:
        self.zone_removed(step.zone, t_s)
        ttl = step.ttl_s
        self.zones.append(
            ZoneVersion(
                step.zone, translate.zone(step.update(), step.zone), t_s, t_s + ttl if ttl else math.inf
            )
        )

    def zone_removed(self, zone_id: str, t_s: float) -> None:
        for i, v in enumerate(self.zones):
            if v.zone_id == zone_id and v.end_s > t_s:
                self.zones[i] = ZoneVersion(v.zone_id, v.zone, v.start_s, t_s)

    def due(self, step: Step, t_s: float) -> bool:
        if step.at_s is not None and t_s < step.at_s:
            return False
        if step.when is not None:
            pos = self.watch.position(step.when.unit)
            if pos is None or math.dist(pos, step.when.of) > step.when.within_m:
                return False
        return True

    def waiting_on(self, t_s: float) -> str:
        """What the timeline waits for now, in words: the entry, and its trigger's distance or time."""
        tl = self.script.timeline
        if self.index >= len(tl):
            teams = team_members(self.script)
            due = [
                f"{e.who} to arrive (by {e.arrives_within_s:g} s)"
                for e in self.script.expect
                if e.arrives_within_s is not None
                and not all(
                    u in self.watch.arrived_at_s for u in (teams.get(e.team, ()) if e.team else (e.unit,))
                )
                and t_s <= e.arrives_within_s
            ]
            pending = self.s.pending()
            if pending:  # goals and threats no planner has taken yet (wire.delivery)
                due.append(f"a planner to take {len(pending)} write{'s' if len(pending) > 1 else ''}")
            return "timeline done; waiting for " + ", ".join(due) if due else "timeline done"
        step = tl[self.index]
        head = f"waiting on timeline[{self.index}] ({step.describe(self.show)})"
        if self.wait_until is not None:
            return f"{head}: {max(self.wait_until - t_s, 0.0):.1f} s left"
        if step.at_s is not None and t_s < step.at_s:
            return f"{head}: until t={step.at_s:g} s"
        if step.when is not None:
            w = step.when
            pos = self.watch.position(w.unit)
            where = "not seen yet" if pos is None else f"now {math.dist(pos, w.of):.1f} m away"
            of = self.show(w.of) if self.show is not None else f"({w.of[0]:g}, {w.of[1]:g})"
            return f"{head}: {w.unit} within {w.within_m:g} m of {of}, {where}"
        return head

    def advance(self, t_s: float, wall_s: float) -> None:
        tl = self.script.timeline
        while self.index < len(tl):
            step = tl[self.index]
            if self.wait_until is not None:
                if t_s < self.wait_until:
                    return
                self.wait_until = None
                self.index += 1
                continue
            if not self.due(step, t_s):
                return
            where = self.watch.position(step.when.unit) if step.when is not None else None
            self.fire(step, t_s)
            self.fired.append(Fired(self.index, t_s, wall_s, step, where))
            trig = ""
            if where is not None and step.when is not None:
                trig = f"  (when {step.when.unit} at {self.coords.point(where, digits=2)})"
            self.say(f"t={t_s:7.2f}s  {step.describe(self.show)}{trig}")
            if isinstance(step, Wait):
                self.wait_until = t_s + step.seconds
            else:
                self.index += 1

    def fire(self, step: Step, t_s: float) -> None:
        s, m, w = self.s, self.m, self.watch
        if isinstance(step, AddThreat):
            update = step.update()
            s.put(keys.threat(m, step.threat), encode(update))
            w.threat_put(step.threat, update, t_s)
        elif isinstance(step, MoveThreat):
            old = w.current(step.threat)
            if old is None:  # removed or expired meanwhile: nothing to move
                self.say(f"t={t_s:7.2f}s  threat {step.threat} is gone; move skipped")
                return
            facing = old.update.facing_deg if step.facing_deg is None else step.facing_deg
            moved = msgspec.structs.replace(old.update, position=step.position, facing_deg=facing)
            s.put(keys.threat(m, step.threat), encode(moved))
            w.threat_put(step.threat, moved, t_s)
        elif isinstance(step, RemoveThreat):
            s.delete(keys.threat(m, step.threat))
            w.threat_removed(step.threat, t_s)
        elif isinstance(step, SetGoal):
            s.put(keys.unit_goal(m, step.unit), encode(step.goal()))
        elif isinstance(step, CancelGoal):
            s.delete(keys.unit_goal(m, step.unit))
        elif isinstance(step, AddZone):
            s.put(keys.zone(m, step.zone), encode(step.update()))
            self.zone_put(step, t_s)
        elif isinstance(step, RemoveZone):
            s.delete(keys.zone(m, step.zone))
            self.zone_removed(step.zone, t_s)
        elif isinstance(step, AddTeam):
            s.put(keys.team(m, step.team), encode(step.update()))
        elif isinstance(step, RemoveTeam):
            s.delete(keys.team(m, step.team))


def _zone_reframed(step: AddZone, conv: Callable[[tuple[float, float]], tuple[float, float]]) -> AddZone:
    if step.circle is not None:
        circle = msgspec.structs.replace(step.circle, centre=conv(step.circle.centre))
        return msgspec.structs.replace(step, circle=circle)
    assert step.polygon is not None
    rings = [[conv((x, y)) for x, y in ring] for ring in step.polygon]
    return msgspec.structs.replace(step, polygon=rings)


def script_in_planner_frame(
    script: Script, planner: Origin | None, mission: str
) -> tuple[Script, str | None]:
    """``script`` with every position (and trigger point) in the planner's frame, and a line to say so.

    Raises:
        InputError: at ``origin``, when the script has one and the planner none (naming both).
    """
    conv = reframe(script.origin, planner, mission, "script")
    if conv is None:
        return script, None
    steps: list[Step] = []
    for step in script.timeline:
        if isinstance(step, AddZone):
            step = _zone_reframed(step, conv)
        if isinstance(step, AddThreat | MoveThreat | SetGoal):
            step = msgspec.structs.replace(step, position=conv(step.position))
        if isinstance(step, AddTeam) and step.goal is not None:
            step = msgspec.structs.replace(
                step, goal=msgspec.structs.replace(step.goal, position=conv(step.goal.position))
            )
        if step.when is not None:
            step = msgspec.structs.replace(
                step, when=msgspec.structs.replace(step.when, of=conv(step.when.of))
            )
        steps.append(step)
    return msgspec.structs.replace(script, origin=planner, timeline=steps), conv.line("script")


def run_inject(
    session: Any,
    script: Script,
    mission: str = keys.DEFAULT_MISSION,
    speed_up: float = 1.0,
    say: Callable[[str], None] = print,
    stop: threading.Event | None = None,
    clock: Callable[[], float] = time.monotonic,
    ready: threading.Event | None = None,
    mission_clock: Callable[[], float] | None = None,
    on_wait: Callable[[float, int, str], None] | None = None,
    ready_after_acks: bool = False,
    coords: str | None = None,
) -> InjectReport:
    """Play ``script`` on an open session and judge it.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        script: a validated script.
        mission: the mission's key chunk.
        speed_up: script seconds per wall second.
        say: where progress lines go.
        stop: set it to end early (the report then judges what was seen).
        clock: monotonic wall seconds.
        ready: set once the entries due at the start have been sent (and the
            timeline waits for a later trigger), so a caller can start units after them.
        mission_clock: the script's seconds, when another part owns the mission clock
            (``pfp demo`` passes its fleet's simulated time); else wall seconds x ``speed_up``.
        ready_after_acks: set ``ready`` only once a planner has also taken what was sent
            (``pfp inject SCENARIO``: its unit starts when the threats and the goal are in force).
        on_wait: called each round with the script time, the entries done and what the timeline waits for.
        coords: how the lines show positions (``--coords``: latlon, metres, mgrs; None: latlon
            with the script's or the planner's origin, else metres).
    """
    import zenoh

    m = keys.check_chunk(mission, "--mission")
    stop = stop or threading.Event()
    if script.origin is not None:  # before anything is sent: metres from two origins never mix
        answered, origin = learn_planner_origin(session, m, stop, say, "script")
        if answered:
            script, line = script_in_planner_frame(script, origin, m)
            if line is not None:
                say(line)
    inbox: queue.Queue[tuple[str, str, Any]] = queue.Queue()

    def on_state(sample: zenoh.Sample) -> None:  # decode and enqueue, nothing more
        with contextlib.suppress(InputError):  # the planner rejects it and says so on event/rejected
            uid = keys.parse(str(sample.key_expr)).id
            inbox.put(("state", uid, decode_unit_state(sample.payload.to_bytes())))

    def on_direction(sample: zenoh.Sample) -> None:
        try:
            d = decode_direction(sample.payload.to_bytes())
            inbox.put(("status", keys.parse(str(sample.key_expr)).id, d.status.value))
        except InputError:
            pass

    def on_event(sample: zenoh.Sample) -> None:
        try:
            ev = decode_event(sample.payload.to_bytes())
        except InputError:
            return
        if isinstance(ev, ArrivedEvent):
            inbox.put(("arrived", ev.unit, None))

    subs = [
        session.declare_subscriber(keys.unit_states_any(m), on_state),
        session.declare_subscriber(keys.unit_directions(m), on_direction),
        session.declare_subscriber(keys.events(m), on_event),
    ]
    run = _Runner(script, session, m, say, _shown_coords(session, script, m, coords, stop, say))
    w = run.watch
    t0 = clock()
    t_s = 0.0
    reason = ""
    say(
        f"inject {script.name}: {len(script.timeline)} actions, {len(script.expect)} expectations, x{speed_up:g}"
    )
    try:
        while True:
            batch: list[tuple[str, str, Any]] = []
            try:
                batch.append(inbox.get(timeout=0.005))
                while True:
                    batch.append(inbox.get_nowait())
            except queue.Empty:
                pass
            t_s = mission_clock() if mission_clock is not None else (clock() - t0) * speed_up
            for kind, uid, payload in batch:
                if kind == "state":
                    w.on_state(uid, payload.position, t_s)
                elif kind == "status":
                    w.on_status(uid, payload, t_s)
                else:
                    w.on_arrived_event(uid, t_s)
            run.advance(t_s, clock())
            if ready is not None and not (ready_after_acks and run.s.pending()):
                ready.set()
            if on_wait is not None:
                on_wait(t_s, run.index, run.waiting_on(t_s))
            if run.index >= len(script.timeline) and _settled(script, w, t_s) and not run.s.pending():
                reason = "timeline done, expectations settled"  # and every write taken by a planner
                break
            if t_s >= script.duration_s:
                reason = f"duration {script.duration_s:g} s reached"
                break
            if stop.is_set():
                reason = "stopped"
                break
    finally:
        run.s.close()
        for sub in subs:
            with contextlib.suppress(Exception):  # already gone with the session
                sub.undeclare()
    say(f"t={t_s:7.2f}s  inject stops: {reason}")
    verdicts = [judge(e, w, run.zones, team_members(script)) for e in script.expect]
    unfired = list(range(run.index, len(script.timeline)))
    return InjectReport(script, run.fired, unfired, verdicts, w, t_s, t0, speed_up, reason, coords=run.coords)


def _shown_coords(
    session: Any,
    script: Script,
    mission: str,
    flag: str | None,
    stop: threading.Event,
    say: Callable[[str], None],
) -> Coords:
    """How the lines show positions (``--coords``): from the script's origin, else the planner's.

    Asked for lat/lon or MGRS with a script in plain metres, it waits for a planner's
    origin; by default it asks once and shows metres if none answers yet.
    """
    origin = script.origin
    if origin is None and flag != "metres":
        origin = (
            learn_planner_origin(
                session, mission, stop, say, "script", f"--coords {flag} shows positions from its origin"
            )[1]
            if flag is not None
            else planner_origin(session, mission)[1]
        )
        if origin is None and flag is not None:
            say(f"--coords {flag}: neither the script nor the planner has an origin; positions are in metres")
    return Coords.choose(flag, origin, strict=False)


def report_lines(rep: InjectReport) -> list[str]:
    """The verdicts as text, one line each, then the overall result."""
    out = []
    for i in rep.unfired:
        show = rep.coords.point if rep.coords.geodetic else None
        out.append(f"  FAIL  timeline[{i}] ({rep.script.timeline[i].describe(show)}) never fired")
    for v in rep.verdicts:
        out.append(f"  {'PASS' if v.held else 'FAIL'}  {v.expect.describe()}: {v.detail}")
    held = sum(v.held for v in rep.verdicts)
    out.append(f"{held}/{len(rep.verdicts)} expectations held" + ("" if rep.ok else "; FAILED"))
    return out


def main(
    script: Script,
    mission: str,
    speed_up: float,
    conf: Any,
    progress_s: float = 5.0,
    stop: threading.Event | None = None,
    coords: str | None = None,
) -> int:
    """``pfp inject``: open a session from ``conf``, play with progress, print the report; 0 iff all held.

    ``stop`` ends the script early (SIGTERM, SIGINT): the report then judges what was seen.

    Raises:
        ZenohError: the session cannot be opened (``Unreachable`` when no router answers).
    """
    from pfp_clients.common import open_session_waiting
    from pfp_clients.progress import Progress

    total = len(script.timeline)
    session = open_session_waiting(conf, print, stop)  # started before `pfp serve`: wait for its router
    if session is None:  # stopped while waiting
        return 1
    with session, Progress(progress_s, total=total) as progress:

        def on_wait(t_s: float, done: int, what: str) -> None:
            progress.update(f"t={t_s:7.2f}s  {what}", done)

        if stop is not None and stop.is_set():  # a signal while the session opened
            return 1
        rep = run_inject(
            session, script, mission, speed_up, say=progress.say, stop=stop, on_wait=on_wait, coords=coords
        )
    for line in report_lines(rep):
        print(line)
    return 0 if rep.ok else 1
