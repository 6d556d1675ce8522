"""The handheld's I/O: its Zenoh session and the NMEA reader thread, both feeding one queue.

Zenoh callbacks and the reader thread only decode and enqueue (``Inbound``
items on a bounded ``queue.Queue`` with ``put_nowait``), so nothing ever
blocks Zenoh's receive path; the Textual app drains the queue on a timer.
``open_link`` opens a client-mode session at once (or raises) and closes it
on the way out; ``RetryingLink`` is what ``pfp handheld`` uses: it starts
with the router down, says so (``LinkDown``), and keeps trying until it is
up (``LinkUp``).  Besides directions, a link reports the unit's goal being
set or cancelled by anyone (``GoalIn``) and a planner's liveliness token
appearing (``PlannerUp``), so the handheld can re-send its goal to a
restarted planner and still respect a cancel.

With a GPS, positions are metres from ``--origin``; ``RetryingLink`` checks
that origin against the planner's own (its status) once connected and again
whenever a planner comes up (``OriginChecked``).  When they differ no
position is sent, so the planner never guides a soldier from a place
kilometres off; the screen says why and which origin to use.

The NMEA reader paces a regular file by the sentences' own UTC times (or at
``rate_hz``), and reads lines of bounded length, so a binary file is a run
of rejected sentences that ends, never a spinning core.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from typing import Any

import zenoh

from pfp_clients.frames import judge_origin, learn_planner_origin
from pfp_service.errors import InputError, ZenohError, map_zenoh_errors
from pfp_service.geo import Origin
from pfp_service.node.config import client_zenoh_config
from pfp_service.wire import (
    Direction,
    Goal,
    UnitState,
    decode_direction,
    decode_goal,
    encode,
    keys,
)
from pfp_service.wire.delivery import Deliverer
from pfp_service.wire.encoding import zenoh_encoding

__all__ = [
    "DirectionIn",
    "FixIn",
    "GoalIn",
    "Inbound",
    "Link",
    "LinkDown",
    "LinkUp",
    "NmeaEnded",
    "NmeaRejected",
    "NoFixIn",
    "OriginChecked",
    "OriginLearnt",
    "PlannerUp",
    "RetryingLink",
    "WireRejected",
    "client_config",
    "offer",
    "open_link",
]

INBOX_DEPTH = 1024


@dataclass(frozen=True, slots=True)
class DirectionIn:
    direction: Direction


@dataclass(frozen=True, slots=True)
class WireRejected:
    reason: str


@dataclass(frozen=True, slots=True)
class FixIn:
    x_m: float
    y_m: float


@dataclass(frozen=True, slots=True)
class NoFixIn:
    pass


@dataclass(frozen=True, slots=True)
class NmeaRejected:
    reason: str


@dataclass(frozen=True, slots=True)
class NmeaEnded:
    reason: str


@dataclass(frozen=True, slots=True)
class LinkUp:
    where: str


@dataclass(frozen=True, slots=True)
class LinkDown:
    reason: str


@dataclass(frozen=True, slots=True)
class PlannerUp:
    planner: str


@dataclass(frozen=True, slots=True)
class OriginChecked:
    """``--origin`` against the planner's (``frames.judge_origin``): ``ok`` False, no position is sent."""

    ok: bool
    text: str  # why not, or a line to show ("" when the two agree)


@dataclass(frozen=True, slots=True)
class OriginLearnt:
    """The planner's origin, asked once connected and whenever a planner comes up (``None``: it has none)."""

    origin: Origin | None


@dataclass(frozen=True, slots=True)
class GoalIn:
    """The unit's goal as put on the wire by anyone (``None``: cancelled)."""

    position: tuple[float, float] | None


Inbound = (
    DirectionIn
    | OriginLearnt
    | WireRejected
    | FixIn
    | NoFixIn
    | NmeaRejected
    | NmeaEnded
    | LinkUp
    | LinkDown
    | PlannerUp
    | OriginChecked
    | GoalIn
)


def _quiet(_line: str) -> None:
    """Positions go out while no planner has answered: nothing to say of the wait."""


def offer(inbox: queue.Queue[Inbound], item: Inbound) -> None:
    """Enqueue without ever blocking; when the UI has fallen this far behind, drop."""
    with suppress(queue.Full):
        inbox.put_nowait(item)


def client_config(endpoints: list[str]) -> zenoh.Config:
    """A client-mode config that connects to ``endpoints`` only (no multicast scouting)."""
    return client_zenoh_config(endpoints)


class Link:
    """One unit's side of the wire: state out, directions in, a liveliness token while open."""

    def __init__(
        self,
        session: zenoh.Session,
        mission: str,
        unit: str,
        inbox: queue.Queue[Inbound] | None = None,
        on_planner: Callable[[], None] | None = None,
    ) -> None:
        self.session = session
        self._planner_up = on_planner  # told (on Zenoh's thread: it must not block) when a planner appears
        self.mission = mission
        self.unit = unit
        self.inbox: queue.Queue[Inbound] = inbox if inbox is not None else queue.Queue(INBOX_DEPTH)
        self._state_pub = session.declare_publisher(
            keys.shard_state(mission, unit),  # its shard: a --cluster planner hears its own shards only
            encoding=zenoh_encoding(),
            congestion_control=zenoh.CongestionControl.DROP,
            express=True,
        )
        self._sub = session.declare_subscriber(keys.unit_direction(mission, unit), self._on_direction)
        self._goal_sub = session.declare_subscriber(keys.unit_goal(mission, unit), self._on_goal)
        self._planners = session.liveliness().declare_subscriber(
            keys.alive_planners(mission), self._on_planner
        )
        self._token = session.liveliness().declare_token(keys.alive_unit(mission, unit))
        # the goal is an acknowledged write: put while no planner runs, it is in force once one starts
        # (the screen shows no direction meanwhile; the model also re-sends it until a planner answers)
        self._goals = Deliverer(session, mission)

    @property
    def connected(self) -> bool:
        return True

    def _on_goal(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE:
            offer(self.inbox, GoalIn(None))
            return
        try:
            goal = decode_goal(sample.payload.to_bytes())
        except InputError:
            return  # the planner rejects it and says so on event/rejected
        offer(self.inbox, GoalIn((float(goal.position[0]), float(goal.position[1]))))

    def _on_planner(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            offer(self.inbox, PlannerUp(str(sample.key_expr).rsplit("/", 1)[-1]))
            if self._planner_up is not None:
                self._planner_up()

    def _on_direction(self, sample: zenoh.Sample) -> None:
        # decode and enqueue only: this runs on Zenoh's callback thread
        try:
            d = decode_direction(sample.payload.to_bytes())
        except InputError as exc:
            offer(self.inbox, WireRejected(str(exc)))
            return
        except Exception as exc:  # never let a surprise kill the subscriber silently
            offer(self.inbox, WireRejected(f"{type(exc).__name__}: {exc}"))
            return
        if d.unit != self.unit:
            offer(self.inbox, WireRejected(f"$.unit: direction for {d.unit!r}, not {self.unit!r}"))
            return
        offer(self.inbox, DirectionIn(d))

    def publish_state(self, state: UnitState) -> None:
        """Put ``unit/{u}/state`` (drops rather than waits under congestion)."""
        self._state_pub.put(encode(state))

    def put_goal(self, goal: Goal) -> None:
        """Put ``unit/{u}/goal``, until a planner acknowledges it (``wire.delivery``)."""
        self._goals.put(keys.unit_goal(self.mission, self.unit), encode(goal))

    def close(self) -> None:
        """Withdraw the token, undeclare, then close the session."""
        self._goals.close()
        for entity in (self._token, self._planners, self._goal_sub, self._sub, self._state_pub):
            with suppress(Exception):  # already gone with the session; closing matters more
                entity.undeclare()
        self.session.close()


@contextmanager
def open_link(endpoints: list[str], mission: str, unit: str) -> Iterator[Link]:
    """Open a client session to ``endpoints`` and the unit's link; close both on exit.

    Raises:
        InputError: ``--connect``, when no router answers (client mode fails at once).
    """
    keys.check_chunk(mission, "--mission")
    keys.check_chunk(unit, "--unit")
    with map_zenoh_errors("--connect"):
        session = zenoh.open(client_config(endpoints))
    try:
        link = Link(session, mission, unit)
    except BaseException:
        session.close()
        raise
    try:
        yield link
    finally:
        link.close()


class RetryingLink:
    """A ``Link`` that connects in the background: it starts with the router down and retries.

    Until it is up, states and goals are dropped (the handheld shows STALE, and
    re-sends its goal once a planner answers).  Feeds ``LinkDown(reason)`` when a
    try fails with a new reason and ``LinkUp`` once connected, on ``inbox``.
    """

    def __init__(
        self,
        conf_factory: Callable[[], Any],
        where: str,
        mission: str,
        unit: str,
        retry_s: float = 1.0,
        origin: Origin | None = None,
    ) -> None:
        self.mission = keys.check_chunk(mission, "--mission")
        self.origin = origin  # the GPS's frame: checked against the planner's once connected
        self.origin_refused = False  # it differs: no position is sent
        self._recheck = threading.Event()
        self.unit = keys.check_chunk(unit, "--unit")
        self.where = where
        self.retry_s = retry_s
        self.inbox: queue.Queue[Inbound] = queue.Queue(INBOX_DEPTH)
        self._conf_factory = conf_factory
        self._link: Link | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._connect, name="handheld-connect", daemon=True)
        self._thread.start()

    @property
    def connected(self) -> bool:
        return self._link is not None

    def _connect(self) -> None:
        last = ""
        while not self._stop.is_set():
            try:
                with map_zenoh_errors("--connect"):
                    session = zenoh.open(self._conf_factory())
            except ZenohError as exc:
                if exc.reason != last:
                    last = exc.reason
                    offer(self.inbox, LinkDown(f"{exc.reason}; retrying every {self.retry_s:g} s"))
                self._stop.wait(self.retry_s)
                continue
            with self._lock:
                if self._stop.is_set():
                    session.close()
                    return
                self._link = Link(session, self.mission, self.unit, self.inbox, self._recheck.set)
            offer(self.inbox, LinkUp(self.where))
            self._watch_origin(session, self.origin)
            return

    def _watch_origin(self, session: zenoh.Session, mine: Origin | None) -> None:
        """Learn the planner's origin (``OriginLearnt``), and judge ``mine`` against it, now and whenever a
        planner comes up; until closed.

        A planner not answering yet is asked again every second
        (``learn_planner_origin``); positions go out meanwhile (as they did
        before any check), and stop the moment one answers with another origin.
        Without ``mine`` (the simulated walk is in the planner's metres) the
        learnt origin only lets the screen show lat/lon and MGRS.
        """
        self._recheck.set()
        while self._recheck.wait() and not self._stop.is_set():
            self._recheck.clear()
            try:
                answered, planner = learn_planner_origin(
                    session, self.mission, self._stop, _quiet, "handheld"
                )
            except Exception:  # the session is closing: nothing left to check
                return
            if not answered:  # closed meanwhile
                return
            offer(self.inbox, OriginLearnt(planner))
            if mine is None:
                continue
            try:
                note = judge_origin(planner, self.mission, mine)
            except InputError as err:
                self.origin_refused = True
                offer(self.inbox, OriginChecked(False, f"positions not sent: {err.reason}"))
                continue
            self.origin_refused = False
            offer(self.inbox, OriginChecked(True, note or ""))

    def publish_state(self, state: UnitState) -> None:
        if self._link is not None and not self.origin_refused:
            self._link.publish_state(state)

    def put_goal(self, goal: Goal) -> None:
        if self._link is not None:
            self._link.put_goal(goal)

    def close(self, wait_s: float = 5.0) -> bool:
        """Stop trying (and checking); close the link if it is up.

        The link closes first, so that a planner query in flight on the
        connecting thread ends with it.  Returns whether that thread ended: a
        thread still inside ``zenoh.open`` (a loaded machine, a slow router)
        must not outlive the interpreter's finalisation, which aborts the
        process ("FATAL: exception not rethrown") when the thread comes back.
        """
        self._stop.set()
        self._recheck.set()
        with self._lock:
            if self._link is not None:
                self._link.close()
                self._link = None
        self._thread.join(timeout=wait_s)
        return not self._thread.is_alive()
