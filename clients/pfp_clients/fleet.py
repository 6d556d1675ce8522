"""``pfp fleet``: a headless fleet of simulated vehicles on Zenoh, following the planner's directions.

Each tick every unit whose report is due (at its own ``rate_hz``) publishes
its state (with a fresh ``seq``), the fleet waits for the planner's answers,
then every unit moves ``speed_mps * dt`` along its newest direction, unless it
is in one of its stops (``sim.SimUnit``: real speeds, report rates, stops and
GPS noise, never the planner's step).  Ticks are paced at ``dt / speed_up`` of wall time, so
``--speed-up 10`` runs ten simulated seconds per second; if the planner answers
late the fleet waits up to ``reply_timeout_s`` (lockstep), so acceleration never
outruns the planner.  Nor does it outrun the planner's deliberation: while a
unit's newest direction says a route is being computed off the loop
(``deliberating``), ticks are paced at real time, so a vehicle drives no
further on plain descent while a search runs than a real one would (at
``--speed-up 40`` a 2 s search would otherwise be 80 s of driving, and a
run's outcome would depend on how busy the machine is).  A unit whose answer
still has not come moves along the direction it had, as a vehicle would.  Each unit holds a liveliness token
``mumt/{m}/alive/unit/{u}`` while the fleet runs.

Goals from the team file are put with no ``step``: the planning resolution is
the planner's business, and its guidance holds whatever a vehicle does
between two reports (``core.tracking``).  They are acknowledged writes (``wire.delivery``): put before a planner runs, they are in force once
one starts, and the fleet says it is waiting meanwhile.

A team file with an ``origin`` is checked against the planner's (from its
status) before anything is sent: the same, it runs as written; another, every
start and goal is converted exactly into the planner's frame (through lat/lon)
and the fleet says so; a planner without an origin is refused in one line
naming both, since metres from two different points cannot be mixed.

Positions in its lines and its summary are shown as ``coords`` says
(``FleetOptions.coords``, ``--coords``): lat/lon with the metres from the
origin when the team or the planner has one, else metres.  Asked for lat/lon
or MGRS with a team in plain metres, the fleet waits for the planner's origin
first; by default it asks once, and shows metres if no planner answers yet.
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec

from pfp_clients.frames import learn_planner_origin, planner_origin, reframe
from pfp_clients.sim import SimUnit
from pfp_service.coords import Coords
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.natsort import natural_key
from pfp_service.team import Team, UnitSpec, team_updates, zone_updates
from pfp_service.wire import (
    Direction,
    DirectionStatus,
    Goal,
    GoalMobility,
    TeamUpdate,
    decode_direction,
    decode_goal,
    encode,
    keys,
)
from pfp_service.wire.delivery import Deliverer
from pfp_service.wire.encoding import zenoh_encoding

__all__ = ["FleetOptions", "FleetResult", "in_planner_frame", "run_fleet", "summary_lines"]


@dataclass(frozen=True)
class FleetOptions:
    """How the fleet runs.

    Attributes:
        mission: the mission's key chunk.
        rate_hz: state reports per simulated second, per unit without its own ``rate_hz``.
        speed_up: simulated seconds per wall second.
        duration_s: stop after this much simulated time (None: run until stopped).
        until_arrived: stop as soon as the planner reports every unit arrived.
        set_goals: put the team file's goals (else units wait for goals from elsewhere).
        reply_timeout_s: wall seconds to wait for late answers before moving on.
        coords: how positions are shown (``--coords``: latlon, metres, mgrs; None: latlon
            when an origin is known, else metres).
        gps_sigma_m: each unit's fix error (metres per axis), unless its spec says.
        stops: ``(at_s, for_s)`` halts of each unit, unless its spec says.
        mobility: the mobility class each unit's states carry, unless its spec says (None: none).
        seed: seeds the GPS noise (with each unit's id).
    """

    mission: str = keys.DEFAULT_MISSION
    rate_hz: float = 5.0
    speed_up: float = 1.0
    duration_s: float | None = None
    until_arrived: bool = False
    set_goals: bool = True
    reply_timeout_s: float = 1.0
    coords: str | None = None
    gps_sigma_m: float = 0.0
    stops: tuple[tuple[float, float], ...] = ()
    seed: int = 0
    mobility: GoalMobility | None = None

    def unit(self, spec: UnitSpec) -> SimUnit:
        """The simulated vehicle of ``spec``, with the fleet's defaults where the spec says nothing."""
        return SimUnit(
            spec,
            rate_hz=self.rate_hz,
            gps_sigma_m=self.gps_sigma_m,
            stops=self.stops,
            seed=self.seed,
            mobility=self.mobility,
        )


@dataclass
class FleetResult:
    """How the run ended: the units (with tracks), the simulated time, and why it stopped."""

    units: list[SimUnit]
    t_s: float
    ticks: int
    late_replies: int
    reason: str
    coords: Coords = field(default_factory=Coords)

    @property
    def all_arrived(self) -> bool:
        return all(u.arrived for u in self.units)


def _goal_of(u: SimUnit) -> Goal | None:
    if u.spec.goal is None:
        return None
    return Goal(position=u.spec.goal)  # no step: the planner's resolution is its own


def in_planner_frame(team: Team, planner: Origin | None, mission: str) -> tuple[Team, str | None]:
    """``team`` in the planner's frame, and a line to say when it was converted (``frames.reframe``).

    Raises:
        InputError: at ``origin``, when the team has one and the planner none (naming both).
    """
    conv = reframe(team.origin, planner, mission, "team")
    if conv is None:
        return team, None

    def at(p: tuple[float, float] | None) -> tuple[float, float] | None:
        return None if p is None else conv(p)

    units = [msgspec.structs.replace(u, start=at(u.start), goal=at(u.goal)) for u in team.units]
    zones = [  # keep-out zones move with the frame too
        msgspec.structs.replace(
            z,
            polygon=None if z.polygon is None else [[conv(p) for p in ring] for ring in z.polygon],
            circle=None
            if z.circle is None
            else msgspec.structs.replace(z.circle, centre=conv(z.circle.centre)),
        )
        for z in team.zones
    ]
    return msgspec.structs.replace(team, origin=planner, units=units, zones=zones), conv.line("team")


def team_roles(team: TeamUpdate) -> list[str]:
    """A team's roles in words, for its line: ``lead r1``, ``follow m1 m2``, ``controller m1 of r1 r2``."""
    out = [f"lead {team.lead}"] if team.lead else []
    out += [f"follow {' '.join(team.follow)}"] if team.follow else []
    out += [f"controller {team.controller} of {' '.join(team.robots)}"] if team.controller else []
    return out or [f"members {' '.join(team.members)}"]


def run_fleet(
    session: Any,
    team: Team,
    opts: FleetOptions,
    stop: threading.Event | None = None,
    say: Callable[[str], None] = print,
    on_tick: Callable[[float, Sequence[SimUnit]], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> FleetResult:
    """Run the fleet on an open session until arrival, the duration or ``stop``.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        team: the units.
        opts: rates, acceleration and stop conditions.
        stop: set it to end the run early.
        say: where progress lines go (each starts with the simulated time).
        on_tick: called after every tick with the simulated time and the units.
        clock: monotonic wall seconds.
    """
    import zenoh

    m = keys.check_chunk(opts.mission, "--mission")
    stop = stop or threading.Event()
    shown_origin = team.origin
    if team.origin is not None:  # before anything is sent: metres from two origins never mix
        answered, origin = learn_planner_origin(session, m, stop, say, "team")
        if not answered:
            return FleetResult([opts.unit(spec) for spec in team.units], 0.0, 0, 0, "stopped")
        team, line = in_planner_frame(team, origin, m)
        if line is not None:
            say(line)
        shown_origin = team.origin
    elif opts.coords in (
        "latlon",
        "mgrs",
    ):  # shown on the earth: the planner's origin, since the team has none
        why = f"--coords {opts.coords} shows positions from its origin"
        answered, shown_origin = learn_planner_origin(session, m, stop, say, "team", why)
        if not answered:
            return FleetResult([opts.unit(spec) for spec in team.units], 0.0, 0, 0, "stopped")
        if shown_origin is None:
            say(
                f"--coords {opts.coords}: neither the team nor the planner has an origin; positions are in metres"
            )
    elif opts.coords is None:  # the default: lat/lon if a planner already running has an origin
        shown_origin = planner_origin(session, m)[1]
    coords = Coords.choose(opts.coords, shown_origin, strict=False)
    units = [opts.unit(spec) for spec in team.units]
    by_id = {u.id: u for u in units}
    dt_s = 1.0 / max(u.rate_hz for u in units)  # a tick per report of the fastest unit
    inbox: queue.Queue[tuple[str, Direction]] = queue.Queue()

    def on_direction(sample: zenoh.Sample) -> None:  # decode and enqueue, nothing more
        try:
            uid = keys.parse(str(sample.key_expr)).id
            if uid in by_id:
                inbox.put((uid, decode_direction(sample.payload.to_bytes())))
        except InputError:
            pass  # not ours to judge: the planner's own rejections are events

    new_planner = threading.Event()

    def on_planner(sample: zenoh.Sample) -> None:  # a planner (re)started: goals are put again
        if sample.kind == zenoh.SampleKind.PUT:
            new_planner.set()

    cancelled: set[str] = set()  # goals someone cancelled on the wire are not put again
    on_wire: dict[str, Goal] = {}  # the goal last put on the wire for a unit, by anyone (a map, a commander)

    def on_goal(sample: zenoh.Sample) -> None:
        with contextlib.suppress(InputError):
            uid = keys.parse(str(sample.key_expr)).id
            if uid not in by_id:
                return
            if sample.kind == zenoh.SampleKind.DELETE:
                cancelled.add(uid)
                on_wire.pop(uid, None)
            else:
                on_wire[uid] = decode_goal(sample.payload.to_bytes())
                cancelled.discard(uid)

    enc = zenoh_encoding()
    declared: list[Any] = [
        session.declare_subscriber(keys.unit_directions(m), on_direction),
        session.liveliness().declare_subscriber(keys.alive_planners(m), on_planner),
        session.declare_subscriber(keys.goals(m), on_goal),
    ]
    reput_at: dict[str, float] = {}

    def reput(u: SimUnit, why: str) -> None:
        """Belt and braces: a planner that lost a unit's goal gets it again (at most every 2 s).

        The goal is the one last put on the wire (the team file's until somebody puts another).
        """
        goal = (
            (on_wire.get(u.id) or _goal_of(u))
            if opts.set_goals and not u.arrived and u.id not in cancelled
            else None
        )
        if goal is None or clock() - reput_at.get(u.id, -1e9) < 2.0:
            return
        reput_at[u.id] = clock()
        goals.put(keys.unit_goal(m, u.id), encode(goal))
        say(f"t={t_s:7.2f}s  {u.id} goal put again ({why})")

    # goals are acknowledged writes: put before a planner runs, in force once one starts
    goals = Deliverer(session, m, lambda line: say(f"t={t_s:7.2f}s  {line}"))
    tokens = [session.liveliness().declare_token(keys.alive_unit(m, u.id)) for u in units]
    pubs = {u.id: session.declare_publisher(keys.shard_state(m, u.id), encoding=enc) for u in units}
    t_s, tick, late, real_time = 0.0, 0, 0, 0
    reason = "stopped"
    last_answer = clock()
    silent_warned = False

    def drain(deadline: float, need: dict[str, int] | None) -> None:
        while True:
            if need is not None and all(by_id[uid].answered >= seq for uid, seq in need.items()):
                return
            left = deadline - clock()
            try:
                uid, d = inbox.get(timeout=max(left, 0.0)) if left > 0 else inbox.get_nowait()
            except queue.Empty:
                return
            nonlocal last_answer
            last_answer = clock()
            line = by_id[uid].on_direction(d, t_s, coords.point)
            if line is not None:
                say(f"t={t_s:7.2f}s  {line}")
            if d.status is DirectionStatus.NO_GOAL and not d.reason and tick > 0:
                # a reason says why the goal went (cancelled: the planner saw a delete whose own sample may
                # reach us later; refused): the same goal again would not help. None: the planner lost it.
                reput(by_id[uid], "the planner answered no_goal")

    say(f"fleet {team.name}: {len(units)} units, {opts.rate_hz:g} Hz, speed-up x{opts.speed_up:g}")
    try:
        started = clock()
        while not stop.is_set():
            tick_start = clock()
            if tick == 0 and opts.set_goals:  # goals first: the first report starts each stepper
                for zid, zone in zone_updates(team):  # the team's keep-out zones before its goals
                    goals.put(keys.zone(m, zid), encode(zone))
                    say(f"t={t_s:7.2f}s  keep-out zone {zid} put")
                for tid, tm in team_updates(team):  # and its teams: their roles judge the first directions
                    goals.put(keys.team(m, tid), encode(tm))
                    say(f"t={t_s:7.2f}s  team {tid} put: {', '.join(team_roles(tm))}")
                for u in units:
                    goal = _goal_of(u)
                    if goal is not None:
                        goals.put(keys.unit_goal(m, u.id), encode(goal))
                        say(f"t={t_s:7.2f}s  {u.id} ({u.spec.kind.value}) goal {coords.point(goal.position)}")
            if new_planner.is_set() and tick > 0:
                new_planner.clear()
                for u in units:
                    reput(u, "a planner started")
            need: dict[str, int] = {}
            for u in units:
                if u.due(t_s):
                    pubs[u.id].put(encode(u.state(t_s)))
                    need[u.id] = u.seq
            # pace the tick (at real time while a route is deliberated), then (lockstep) wait a while
            # longer for answers still missing
            speed_up = opts.speed_up
            if speed_up > 1.0 and any(u.deliberating for u in units):
                speed_up, real_time = 1.0, real_time + 1
            drain(tick_start + dt_s / speed_up, None)
            if clock() - last_answer < 2 * opts.reply_timeout_s:  # lockstep only while a planner answers
                drain(clock() + opts.reply_timeout_s, need)
            late += sum(1 for uid, seq in need.items() if by_id[uid].answered < seq)
            silent_s = clock() - last_answer
            if silent_s > 3.0 and not silent_warned:
                say(f"t={t_s:7.2f}s  no direction from any planner of mission {m!r} for {silent_s:.0f} s")
            silent_warned = silent_s > 3.0
            tick += 1
            t_s = tick * dt_s
            now = clock()
            for u in units:
                u.advance(dt_s, t_s, now)
            if on_tick is not None:
                on_tick(t_s, units)
            if opts.until_arrived and all(u.arrived for u in units):
                reason = "all arrived"
                break
            if opts.duration_s is not None and t_s >= opts.duration_s - 1e-9:
                reason = f"duration {opts.duration_s:g} s reached"
                break
        wall = clock() - started
        paced = f"; {real_time} at real time while a route was deliberated" if real_time else ""
        say(f"t={t_s:7.2f}s  fleet stops: {reason} ({tick} ticks in {wall:.1f} s wall{paced})")
    finally:
        goals.close()
        for d in [*declared, *pubs.values(), *tokens]:
            with contextlib.suppress(Exception):  # already gone with the session: nothing to release
                d.undeclare()
    return FleetResult(units, t_s, tick, late, reason, coords)


def summary_lines(result: FleetResult) -> list[str]:
    """A plain-text table, units in natural order: unit, kind, status, arrival time, path length, position."""
    rows = [("unit", "kind", "speed", "status", "arrived at", "path m", "position")]
    units = sorted(result.units, key=lambda u: natural_key(u.id))
    for u, pos in zip(units, result.coords.points([u.position for u in units])):
        arrived = f"{u.arrived_at_s:.1f} s" if u.arrived_at_s is not None else "-"
        status = u.status + (f" ({u.trapped_reason})" if u.trapped_reason else "")
        rows.append(
            (
                u.id,
                u.spec.kind.value,
                f"{u.spec.speed_mps:g}",
                status,
                arrived,
                f"{u.path_length_m():.1f}",
                pos,
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def counts(units: Sequence[SimUnit], silent_after: int) -> dict[str, int]:
    """How many units are en route (or escaping), arrived, trapped, and stale.

    A unit is stale when its newest direction answers a report more than
    ``silent_after`` reports old (or none came yet).
    """
    out = {"en route": 0, "arrived": 0, "trapped": 0, "stale": 0}
    for u in units:
        if u.seq - u.answered > silent_after:
            out["stale"] += 1
        elif u.arrived:
            out["arrived"] += 1
        elif u.status == "trapped":
            out["trapped"] += 1
        else:
            out["en route"] += 1
    return out


def progress_line(t_s: float, units: Sequence[SimUnit], silent_after: int) -> str:
    """``t=  12.00s  50 units: 31 en route, 17 arrived, 1 trapped, 1 stale``."""
    c = counts(units, silent_after)
    return f"t={t_s:7.2f}s  {len(units)} units: " + ", ".join(f"{n} {k}" for k, n in c.items())


def main(
    team: Team,
    opts: FleetOptions,
    conf: Any,
    stop: threading.Event | None = None,
    progress_s: float = 5.0,
) -> int:
    """``pfp fleet``: open a session from ``conf``, run with progress, print the summary.

    Returns:
        0, or 1 when ``until_arrived`` was asked and some unit did not arrive.

    Raises:
        ZenohError: the session cannot be opened (``Unreachable`` when no router answers).
    """
    from pfp_clients.common import open_session_waiting
    from pfp_clients.progress import Progress

    silent_after = max(round(2 * opts.rate_hz), 2)  # about two simulated seconds without an answer
    session = open_session_waiting(conf, print, stop)  # started before `pfp serve`: wait for its router
    if session is None:  # stopped while waiting
        return 0
    with session, Progress(progress_s, total=len(team.units)) as progress:

        def on_tick(t_s: float, units: Sequence[SimUnit]) -> None:
            progress.update(progress_line(t_s, units, silent_after), sum(u.arrived for u in units))

        result = run_fleet(session, team, opts, stop, say=progress.say, on_tick=on_tick)
    for line in summary_lines(result):
        print(line)
    if result.late_replies:
        print(
            f"{result.late_replies} reports were not answered within the tick plus {opts.reply_timeout_s:g} s"
        )
    return 1 if opts.until_arrived and not result.all_arrived else 0
