"""The handheld's Textual screen: a thin shell over ``HandheldModel`` and a ``Link``.

A timer drains the link's queue (directions, GPS fixes), advances the
simulated walk, publishes the unit's state at ``publish_hz`` and redraws from
``model.view(now)``.  Laid out for a 50x20 terminal; the arrow grows with
the terminal.  Keys: arrows nudge, space pauses the walk, g sets the goal
(a prompt for ``X,Y`` metres, ``58.41N 15.62E`` or an MGRS reference), q
quits, and Ctrl-C quits as an interrupt (exit 130), as in any command.
With the mission origin (``--origin``, or learnt from the planner) the
position is shown as lat/lon or MGRS (``--coords``).
"""

from __future__ import annotations

import asyncio
import contextlib
import queue
import signal
import time
from collections.abc import Callable
from typing import ClassVar

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.css.query import NoMatches
from textual.screen import ModalScreen
from textual.widgets import Input, Label, Static

from pfp_clients.handheld_link import (
    DirectionIn,
    FixIn,
    GoalIn,
    Link,
    LinkDown,
    LinkUp,
    NmeaEnded,
    NmeaRejected,
    NoFixIn,
    OriginChecked,
    OriginLearnt,
    PlannerUp,
    RetryingLink,
    WireRejected,
)
from pfp_clients.handheld_model import HandheldModel, Severity, View, format_duration, threat_bar
from pfp_clients.nmea_feed import NmeaReader
from pfp_service.coords import Coords, parse_point
from pfp_service.geo import Origin
from pfp_service.signals import EXIT_CODES, SIGNALS, SignalStop

__all__ = ["GoalPrompt", "HandheldApp", "parse_goal"]

SEVERITY_STYLES = {Severity.LOW: "bold green", Severity.CAUTION: "bold yellow", Severity.DANGER: "bold red"}
STATUS_STYLES = {
    "EN ROUTE": "bold green",
    "ESCAPING": "bold yellow",
    "TRAPPED": "bold white on red",
    "ARRIVED": "bold cyan",
    "NO GOAL": "bold",
}
# The arrow fills what the other lines leave, within these bounds (rows of two pixels).
ARROW_ROWS = (3, 15)


def parse_goal(text: str, origin: Origin | None = None) -> tuple[float, float] | str:
    """``"120,80"`` metres, ``"58.4105N 15.6213E"`` or an MGRS reference (with ``origin``), or why not."""
    return parse_point(text, origin)


class GoalPrompt(ModalScreen[tuple[float, float] | None]):
    """Asks for a goal: ``X,Y`` metres, or with the origin lat/lon or MGRS; Enter sets it, Escape keeps the old one."""

    CSS = """
    GoalPrompt { align: center middle; }
    #box { width: 46; height: auto; border: round $accent; padding: 0 1; background: $surface; }
    #why { color: $warning; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [Binding("escape", "cancel", "cancel", show=False)]

    def __init__(self, current: tuple[float, float] | None, coords: Coords | None = None) -> None:
        super().__init__()
        self.current = current
        self.coords = coords or Coords()

    def compose(self) -> ComposeResult:
        from textual.containers import Vertical

        with Vertical(id="box"):
            if self.coords.origin is not None:
                yield Label("Goal: X,Y m, 58.41N 15.62E or MGRS (Enter sets, Esc keeps)")
            else:
                yield Label("Goal X,Y in metres (Enter sets, Esc keeps)")
            if self.current is None:
                value = ""
            elif self.coords.geodetic:
                value = self.coords.point(self.current, offset=False)
            else:
                value = f"{self.current[0]:g},{self.current[1]:g}"
            yield Input(value=value, placeholder="120,80", id="goal")
            yield Label("", id="why")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        result = parse_goal(event.value, self.coords.origin)
        if isinstance(result, str):
            self.query_one("#why", Label).update(result)
            return
        self.dismiss(result)

    def action_cancel(self) -> None:
        self.dismiss(None)


class HandheldApp(App[int]):
    """``pfp handheld``: where to go, how far, how dangerous, how fresh."""

    TITLE = "pfp handheld"
    CSS = """
    Screen { layout: vertical; overflow: hidden hidden; }
    Static { width: 100%; height: auto; padding: 0 1; }
    #title { background: $primary-background; color: $text; text-style: bold; }
    #arrow { content-align: center middle; text-align: center; color: $accent; height: 1fr; }
    #bearing { text-align: center; text-style: bold; }
    #status { text-align: center; }
    #keys { dock: bottom; color: $text-muted; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("up", "nudge(0, 1)", "north", show=False),
        Binding("down", "nudge(0, -1)", "south", show=False),
        Binding("left", "nudge(-1, 0)", "west", show=False),
        Binding("right", "nudge(1, 0)", "east", show=False),
        Binding("space", "toggle_walk", "walk", show=False),
        Binding("g", "goal_prompt", "goal", show=False),
        Binding("q", "quit", "quit", show=False),
        # the terminal is raw: Ctrl-C is a key here, not SIGINT; it ends the app as SIGINT would
        Binding("ctrl+c", "interrupt", "interrupt", show=False, priority=True),
    ]

    def __init__(
        self,
        model: HandheldModel,
        link: Link | RetryingLink,
        *,
        mission: str,
        source: str = "sim",
        nmea: NmeaReader | None = None,
        publish_hz: float = 2.0,
        tick_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
        wallclock: Callable[[], float] = time.time,
        stopping: SignalStop | None = None,
        coords: str | None = None,
        origin: Origin | None = None,
        goal_text: str | None = None,
    ) -> None:
        """``coords``: ``--coords`` (``None``: lat/lon once an origin is known); ``origin``: the GPS's
        ``--origin``, else the planner's once learnt; ``goal_text``: a ``--goal`` in lat/lon or MGRS,
        set once the planner's origin is learnt."""
        super().__init__()
        self.goal_text = goal_text
        self.coords_flag = coords
        self.fixed_origin = origin
        self.coords = Coords.choose(coords, origin, strict=False)
        self.origin: Origin | None = origin  # for typed goals in lat/lon or MGRS
        self.stopping = stopping  # SIGTERM and SIGINT end the app (and say which came)
        self.model = model
        self.link = link
        self.mission = mission
        self.source = source
        self.nmea = nmea
        self.publish_period_s = 1.0 / publish_hz
        self.tick_s = tick_s
        self.clock = clock
        self.wallclock = wallclock
        self.last_view: View | None = None
        self.published = 0
        self._last_publish_s = -float("inf")

    # -- layout -------------------------------------------------------------------
    def compose(self) -> ComposeResult:
        for wid in ("title", "arrow", "bearing", "status", "nav", "threat", "age", "pos", "note"):
            yield Static(id=wid, markup=False)
        keys = (
            "←↑↓→ nudge · g goal · q quit"
            if self.source == "nmea"
            else "←↑↓→ nudge · space walk · g goal · q quit"
        )
        yield Static(keys, id="keys", markup=False)

    def on_mount(self) -> None:
        self._home = self.screen  # the goal prompt goes on top; the readouts stay on this one
        if self.stopping is not None:
            loop = asyncio.get_running_loop()
            for sig in SIGNALS:
                with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):  # not main thread
                    loop.add_signal_handler(sig, self._signalled, sig)
            if self.stopping.signalled:  # while the app started
                self.exit()
        if self.nmea is not None:
            self.nmea.start()
        self.set_interval(self.tick_s, self.tick)
        self.tick()

    def _signalled(self, signum: int) -> None:
        assert self.stopping is not None
        self.stopping.note(signum)
        self.exit()

    def action_interrupt(self) -> None:
        """Ctrl-C: quit at once with 130, as SIGINT ends every other command."""
        if self.stopping is not None:
            self.stopping.note(signal.SIGINT)
        self.exit(EXIT_CODES[signal.SIGINT])

    def _learnt(self, origin: Origin | None) -> None:
        if self.fixed_origin is None:  # the GPS's frame is what the screen shows
            self.origin = origin
            self.coords = Coords.choose(self.coords_flag, origin, strict=False)
        if self.goal_text is None:
            return
        if self.origin is None:  # the planner works in bare metres: lat/lon and MGRS mean nothing to it
            self.model.note = f"--goal {self.goal_text}: the planner has no origin; give X,Y in metres"
            return
        goal = parse_goal(self.goal_text, self.origin)
        self.goal_text = None
        if isinstance(goal, str):
            self.model.note = f"--goal: {goal}"
        else:
            self.model.set_goal(goal)

    # -- actions ------------------------------------------------------------------
    def action_nudge(self, east: int, north: int) -> None:
        step = self.model.settings.nudge_m
        self.model.nudge(east * step, north * step)
        self.publish()
        self.redraw()

    def action_goal_prompt(self) -> None:
        def chosen(goal: tuple[float, float] | None) -> None:
            if goal is not None:
                self.model.set_goal(goal)
                self.tick()

        shown = self.coords if self.coords.origin is not None else Coords("metres", self.origin)
        self.push_screen(GoalPrompt(self.model.goal, shown), chosen)

    def action_toggle_walk(self) -> None:
        if self.source == "nmea":  # the receiver gives the position; a simulated walk would fight it
            self.model.note = "no simulated walk: the GPS gives the position"
        else:
            self.model.toggle_walk(self.clock())
        self.redraw()

    # -- the loop -------------------------------------------------------------------
    def tick(self) -> None:
        """Drain the inbox, walk, publish when due, redraw."""
        now = self.clock()
        fixed = False
        while True:
            try:
                item = self.link.inbox.get_nowait()
            except queue.Empty:
                break
            match item:
                case DirectionIn(direction=d):
                    self.model.on_direction(d, self.clock())
                case WireRejected(reason=reason):
                    self.model.on_rejected(reason)
                case FixIn(x_m=x, y_m=y):
                    self.model.on_fix(x, y, self.clock())
                    fixed = True
                case NoFixIn():
                    self.model.on_no_fix()
                case NmeaRejected(reason=reason):
                    self.model.on_nmea_rejected(reason)
                case NmeaEnded(reason=reason):
                    self.model.on_nmea_ended(reason)
                case LinkUp(where=where):
                    self.model.on_link(True, where)
                case LinkDown(reason=reason):
                    self.model.on_link(False, reason)
                case PlannerUp():
                    self.model.on_planner_up()
                case OriginChecked(ok=ok, text=text):
                    self.model.on_origin(ok, text)
                case GoalIn(position=position):
                    self.model.on_goal(position)
                case OriginLearnt(origin=origin):
                    self._learnt(origin)
        now = self.clock()
        self.model.advance(now)
        goal = self.model.goal_to_send(now)
        if goal is not None:
            self.link.put_goal(goal)
        if fixed or now - self._last_publish_s >= self.publish_period_s:
            self.publish()
        self.redraw()

    def publish(self) -> None:
        """Put the unit's state now (nothing before the first GPS fix)."""
        state = self.model.next_state(self.wallclock())
        if state is not None:
            self.link.publish_state(state)
            self.published += 1
        self._last_publish_s = self.clock()

    # -- drawing --------------------------------------------------------------------
    def _arrow_size(self) -> tuple[int, int]:
        """Fill the arrow's widget (as laid out), keeping the pixels square."""
        box = self._home.query_one("#arrow", Static).size
        rows = min(max(box.height, ARROW_ROWS[0]), ARROW_ROWS[1])
        cols = min(2 * rows + 1, max(box.width, 9))
        return cols, rows

    def redraw(self) -> None:
        """Draw the view.  A draw that lands while the app closes (its tick, a key) finds its widgets
        being removed: it stops there, rather than end a soldier's session with a traceback."""
        with contextlib.suppress(NoMatches):
            self._draw()

    def _draw(self) -> None:
        v = self.model.view(self.clock(), self._arrow_size())
        self.last_view = v
        m = self.model
        mode = "GPS" if self.source == "nmea" else ("walk" if v.walking else "paused")
        if self.source == "sim" and m.settings.speed_up != 1.0:
            mode += f" ×{m.settings.speed_up:g}"
        self._set("title", Text(f"{m.settings.unit} · {self.mission} · {mode}"))
        self._set("arrow", Text("\n".join(v.arrow)))
        self._set("bearing", Text(v.bearing))
        status = Text(v.status_label, style=STATUS_STYLES.get(v.status_label, "bold"))
        if v.why:
            status.append(f"  {v.why}", style="dim")
        self._set("status", status)
        dist = "--" if v.distance_m is None else f"{v.distance_m:.1f} m"
        self._set("nav", Text(f"Dist {dist}  ETA {format_duration(v.eta_s)} @{m.eta_speed_mps():.3g} m/s"))
        bar_w = max(min(self.size.width - 28, 20), 5)
        threat = Text("Threat ")
        threat.append(threat_bar(v.threat_fraction, bar_w), style=SEVERITY_STYLES[v.severity])
        threat.append(f" {v.threat_level:.2f} ")
        threat.append(v.severity.value.upper(), style=SEVERITY_STYLES[v.severity])
        self._set("threat", threat)
        self._set("age", self._age_text(v))
        if v.position is None:
            pos = "Pos: no fix yet"
        else:
            where = (
                self.coords.point(v.position, offset=False)
                if self.coords.geodetic
                else f"E {v.position[0]:.1f} N {v.position[1]:.1f} m"
            )
            pos = f"Pos {where}  {v.speed_mps:.1f} m/s"
        self._set("pos", Text(pos))
        self._set("note", Text(v.note, style="yellow", overflow="ellipsis", no_wrap=True))

    def _age_text(self, v: View) -> Text:
        if v.age_s is None:
            label = "NO UPDATE YET" if v.stale else "Waiting for first update"
        elif v.stale:
            label = f"STALE: last update {format_duration(v.age_s)} ago"
        else:
            label = f"Updated {v.age_s:.1f} s ago"
        return Text(f" {label} ", style="bold white on red" if v.stale else "green")

    def _set(self, wid: str, content: Text) -> None:
        self._home.query_one(f"#{wid}", Static).update(content)
