"""What the handheld knows and shows: sans-I/O state, fed directions, fixes and key presses.

Nothing here imports zenoh or textual or reads a clock: every method that
depends on time takes ``now`` (monotonic seconds).  ``HandheldModel`` holds
the unit's position, the last direction and when it came; ``view(now)`` turns
that into a ``View`` of plain values and strings for the screen.  The helpers
(``cardinal``, ``eta_s``, ``arrow_art``, ...) are pure functions.

The display is map-up: the arrow and the bearing are compass directions
(clockwise from north), not relative to where the soldier faces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Final

from pfp_service.wire import (
    Direction,
    DirectionStatus,
    Goal,
    GoalMobility,
    Progress,
    UnitKind,
    UnitState,
)

__all__ = [
    "CARDINALS",
    "ON_FOOT",
    "STATUS_LABELS",
    "HandheldModel",
    "Settings",
    "Severity",
    "View",
    "arrow_art",
    "bearing_text",
    "cardinal",
    "compass_deg",
    "eta_s",
    "format_duration",
    "threat_bar",
    "why_text",
]

CARDINALS: Final = (
    "N", "NNE", "NE", "ENE", "E", "ESE", "SE", "SSE",
    "S", "SSW", "SW", "WSW", "W", "WNW", "NW", "NNW",
)  # fmt: skip

STATUS_LABELS: Final = {
    DirectionStatus.EN_ROUTE: "EN ROUTE",
    DirectionStatus.ESCAPING: "ESCAPING",
    DirectionStatus.TRAPPED: "TRAPPED",
    DirectionStatus.ARRIVED: "ARRIVED",
    DirectionStatus.NO_GOAL: "NO GOAL",
    DirectionStatus.YIELDING: "YIELDING",
}
WAITING_LABEL: Final = "WAITING FOR PLANNER"
ON_FOOT: Final = GoalMobility(kind="foot")  # a handheld is a soldier's: planned round a soldier's slopes
_MOVING: Final = (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING)


class Severity(StrEnum):
    """How worrying the threat level is; the screen colours it."""

    LOW = "low"
    CAUTION = "caution"
    DANGER = "danger"


# Below this ground speed a GPS unit is standing; its ETA then assumes the walking speed.
MOVING_MPS: Final = 0.3
# Fractions of the full-scale threat level where the bar turns yellow, then red.
CAUTION_FRACTION: Final = 0.3
DANGER_FRACTION: Final = 0.6


def cardinal(bearing_deg: float) -> str:
    """The 16-point compass name of a bearing (N, NNE, NE, ...); each covers 22.5°."""
    return CARDINALS[int(((bearing_deg % 360.0) + 11.25) // 22.5) % 16]


def compass_deg(dx: float, dy: float) -> float | None:
    """Compass bearing (clockwise from north, 0-360) of a vector ``(east, north)``; None if zero."""
    if dx == 0.0 and dy == 0.0:
        return None
    return math.degrees(math.atan2(dx, dy)) % 360.0


def bearing_text(bearing_deg: float | None) -> str:
    """``"047° NE"``; ``"---° --"`` without a bearing.  Rounds to whole degrees (360 shows as 000)."""
    if bearing_deg is None:
        return "---° --"
    whole = round(bearing_deg % 360.0) % 360
    return f"{whole:03d}° {cardinal(whole)}"


def eta_s(distance_m: float | None, speed_mps: float) -> float | None:
    """Seconds to walk ``distance_m`` at ``speed_mps``; None if either is unknown or zero speed."""
    if distance_m is None or speed_mps <= 0.0:
        return None
    return distance_m / speed_mps


def format_duration(seconds: float | None) -> str:
    """``"9 s"``, ``"3 min 05 s"``, ``"1 h 02 min"``; ``"--"`` when unknown."""
    if seconds is None or not math.isfinite(seconds):
        return "--"
    s = max(round(seconds), 0)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def threat_bar(fraction: float, width: int) -> str:
    """A bar of ``width`` cells, ``fraction`` (clipped to 0-1) of them full, in eighths."""
    f = min(max(fraction, 0.0), 1.0)
    eighths = round(f * width * 8)
    full, part = divmod(eighths, 8)
    bar = "█" * full + (" ▏▎▍▌▋▊▉"[part] if part else "")
    return bar.ljust(width, "·")[:width]


# -- the big arrow ------------------------------------------------------------------
def _arrow_shape(x: float, y: float) -> bool:
    """The arrow pointing north, in a square of side 2 centred on the origin.

    The tip reaches farther (0.98) than the tail (0.8) or the barbs (0.62), so
    even a coarse picture shows which way it points.
    """
    head = 0.1 <= y <= 0.98 and abs(x) <= 0.62 * (0.98 - y) / 0.88
    shaft = -0.8 <= y <= 0.1 and abs(x) <= 0.2
    return head or shaft


def _ring(x: float, y: float) -> bool:
    return 0.45 <= math.hypot(x, y) <= 0.85 or math.hypot(x, y) <= 0.2


def _cross(x: float, y: float) -> bool:
    return max(abs(x), abs(y)) <= 0.85 and min(abs(x - y), abs(x + y)) <= 0.28


def _dot(x: float, y: float) -> bool:
    return math.hypot(x, y) <= 0.22


def arrow_art(bearing_deg: float | None, width: int = 15, height: int = 7, status: str = "") -> list[str]:
    """A picture ``height`` lines of ``width`` cells: an arrow along ``bearing_deg``.

    Each cell holds two square-ish pixels (``▀``, ``▄``, ``█``), so a 15x7 picture
    is 15x14 pixels.  Without a bearing it shows a ring (``arrived``), a cross
    (``trapped``) or a dot (anything else).
    """
    if bearing_deg is not None:
        b = math.radians(bearing_deg)
        cos_b, sin_b = math.cos(b), math.sin(b)

        def shape(x: float, y: float) -> bool:
            # rotate the screen point back into the north-pointing arrow's frame
            return _arrow_shape(x * cos_b - y * sin_b, x * sin_b + y * cos_b)

    else:
        shape = {"arrived": _ring, "trapped": _cross}.get(status, _dot)
    rows = 2 * height
    half_x, half_y = width / 2.0, rows / 2.0
    scale = min(half_x, half_y)
    lines = []
    for r in range(height):
        chars = []
        for c in range(width):
            x = (c + 0.5 - half_x) / scale
            top = shape(x, (half_y - (2 * r + 0.5)) / scale)
            bottom = shape(x, (half_y - (2 * r + 1.5)) / scale)
            chars.append("█" if top and bottom else "▀" if top else "▄" if bottom else " ")
        lines.append("".join(chars))
    return lines


# -- the model -------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Settings:
    """The handheld's configuration, fixed at start.

    Attributes:
        unit: this unit's id.
        speed_mps: walking speed, for the ETA and the simulated walk.
        speed_up: the simulated walk goes this many times faster (exercises, tests).
        walk: simulate walking along the directions (off when a GPS gives the position).
        stale_after_s: an update older than this is flagged stale.
        threat_full_scale: the threat level drawn as a full bar (with peak intensity
            a threat's centre is its weight, 1.0 by default).
        nudge_m: how far one arrow-key press moves the position.
        goal: ``(x, y)`` in metres to ask the planner for, if any.
        goal_retry_s: re-send the goal this often until the planner acts on it.
        gps: a GPS gives the position (the ETA then uses the measured ground speed).
    """

    unit: str
    speed_mps: float = 1.4
    speed_up: float = 1.0
    walk: bool = True
    stale_after_s: float = 5.0
    threat_full_scale: float = 1.0
    nudge_m: float = 1.0
    goal: tuple[float, float] | None = None
    goal_retry_s: float = 2.0
    gps: bool = False


@dataclass(frozen=True, slots=True)
class View:
    """Everything on the screen at one moment, as plain values."""

    status_label: str
    bearing_deg: float | None
    bearing: str
    arrow: list[str]
    distance_m: float | None
    eta_s: float | None
    threat_level: float
    threat_fraction: float
    severity: Severity
    age_s: float | None
    stale: bool
    position: tuple[float, float] | None
    heading_deg: float | None
    speed_mps: float
    walking: bool
    note: str
    why: str = ""  # the direction's reason and the planner's word on its progress, in words


def why_text(d: Direction | None) -> str:
    """Why the direction says what it says, for a person: its reason, and what the planner sees of the walk."""
    if d is None:
        return ""
    parts = [d.reason] if d.reason else []
    if d.progress is Progress.STALLED:
        parts.append("no progress seen for 10 s")
    elif d.progress is Progress.HOLDING:
        parts.append("holding")
    return "; ".join(parts)


class HandheldModel:
    """The handheld's state machine: inputs in (directions, fixes, nudges, time), state and view out."""

    def __init__(self, settings: Settings, start: tuple[float, float] | None, now: float) -> None:
        self.settings = settings
        self.position = start
        self.heading_deg: float | None = None
        self.speed_mps = 0.0
        self.direction: Direction | None = None
        self.last_update_s: float | None = None
        self.started_s = now
        self.walking = settings.walk
        self.seq = 0
        self.note = ""
        self.counts = {"directions": 0, "rejected": 0, "fixes": 0, "no_fix": 0, "nmea_rejected": 0}
        self._last_advance_s = now
        self._walked_m = 0.0  # since the last direction, so the walk never overshoots the goal
        self._last_fix: tuple[float, float, float] | None = None
        self.goal = settings.goal  # what this handheld asks for: --goal, the g prompt or the wire's
        self.connected = True  # False while the link has no session (the router is down)
        self.link_note = ""
        self.origin_note = ""  # set while --origin differs from the planner's: no position is sent
        self._goal_sent_s: float | None = None
        self._goal_acked = False

    # -- inputs -------------------------------------------------------------------
    def on_direction(self, d: Direction, now: float) -> None:
        """A direction for this unit arrived (already decoded and validated)."""
        self.advance(now)
        self.direction = d
        self.last_update_s = now
        self._walked_m = 0.0
        self.counts["directions"] += 1
        if d.status is not DirectionStatus.NO_GOAL:
            self._goal_acked = True
        elif self.goal is not None and self._goal_acked and not d.reason:
            # the planner lost it (restarted, or raced a goal put). A reason says why it went: cancelled (a
            # delete, whose own sample, GoalIn(None), may reach us after this direction), or refused.
            self._goal_acked = False

    def on_link(self, up: bool, text: str) -> None:
        """The link connected (``up``) or a try failed; ``text`` says where or why."""
        self.connected = up
        self.link_note = "" if up else text
        if up:
            self._goal_sent_s = None  # send the goal at once

    def on_origin(self, ok: bool, text: str) -> None:
        """``--origin`` judged against the planner's: ``ok`` False, positions are not sent (``text`` says why)."""
        self.origin_note = "" if ok else text
        if ok and text:
            self.note = text

    def on_planner_up(self) -> None:
        """A planner's liveliness token appeared: a new planner knows nothing of our goal yet."""
        self._goal_acked = False
        self._goal_sent_s = None

    def on_goal(self, position: tuple[float, float] | None) -> None:
        """The unit's goal as put on the wire by anyone; ``None`` means somebody cancelled it."""
        if position is None:
            self.goal = None
            self.note = "goal cancelled"
        elif position != self.goal:
            self.goal = position
            self._goal_acked = False
            self._goal_sent_s = None

    def set_goal(self, position: tuple[float, float]) -> None:
        """A new goal from the keyboard: sent at the next tick."""
        self.goal = position
        self._goal_acked = False
        self._goal_sent_s = None
        self.note = f"goal set to ({position[0]:g}, {position[1]:g})"

    def on_rejected(self, reason: str) -> None:
        """A direction payload failed to decode; keep the last good one."""
        self.counts["rejected"] += 1
        self.note = f"bad direction: {reason}"

    def on_fix(self, x_m: float, y_m: float, now: float) -> None:
        """A GPS fix in local metres; ground speed and heading come from the previous fix."""
        if self._last_fix is not None:
            px, py, pt = self._last_fix
            dt = now - pt
            moved = math.hypot(x_m - px, y_m - py)
            if dt >= 0.5:  # fixes read in a burst (a file) carry no usable timing
                self.speed_mps = moved / dt
            if moved >= 0.5:  # below GPS noise the heading means nothing
                self.heading_deg = compass_deg(x_m - px, y_m - py)
        self._last_fix = (x_m, y_m, now)
        self.position = (x_m, y_m)
        self.counts["fixes"] += 1
        if self.note.startswith("GPS"):
            self.note = ""

    def on_no_fix(self) -> None:
        """The receiver is talking but has no fix: keep the last position, say so."""
        self.counts["no_fix"] += 1
        self.note = "GPS: no fix"

    def on_nmea_rejected(self, reason: str) -> None:
        """A sentence could not be trusted (checksum, field); it was dropped."""
        self.counts["nmea_rejected"] += 1
        self.note = f"GPS: rejected {reason}"

    def on_nmea_ended(self, reason: str) -> None:
        """The NMEA stream ended or failed; the position stays where the last fix put it."""
        self.note = f"GPS: {reason}"

    def nudge(self, dx_m: float, dy_m: float) -> None:
        """Move by ``(dx_m, dy_m)`` (the arrow keys); the heading follows the nudge."""
        x, y = self.position if self.position is not None else (0.0, 0.0)
        self.position = (x + dx_m, y + dy_m)
        self.heading_deg = compass_deg(dx_m, dy_m)

    def toggle_walk(self, now: float) -> None:
        """Pause or resume the simulated walk."""
        self.advance(now)
        self.walking = not self.walking

    def advance(self, now: float) -> None:
        """Walk along the current direction from the last call until ``now``.

        Only while walking is on, the direction is fresh and says to move; never
        further than the goal the direction reported.
        """
        dt = max(now - self._last_advance_s, 0.0)
        self._last_advance_s = now
        d = self.direction
        if (
            not self.walking
            or d is None
            or d.status not in _MOVING
            or self.position is None
            or self.stale(now)
            or dt == 0.0
        ):
            if self.settings.walk:
                self.speed_mps = 0.0
            return
        step_m = self.settings.speed_mps * self.settings.speed_up * dt
        if d.distance_to_goal is not None:
            step_m = min(step_m, max(d.distance_to_goal - self._walked_m, 0.0))
        dx, dy = d.vector
        norm = math.hypot(dx, dy)
        if norm == 0.0 or step_m == 0.0:
            self.speed_mps = 0.0
            return
        x, y = self.position
        self.position = (x + step_m * dx / norm, y + step_m * dy / norm)
        self._walked_m += step_m
        self.speed_mps = step_m / dt
        self.heading_deg = compass_deg(dx, dy)

    # -- outputs --------------------------------------------------------------------
    def stale(self, now: float) -> bool:
        """True when the last update (or the start, if none came) is older than ``stale_after_s``."""
        if not self.connected or self.origin_note:
            return True
        since = self.last_update_s if self.last_update_s is not None else self.started_s
        return now - since > self.settings.stale_after_s

    def next_state(self, t: float | None = None) -> UnitState | None:
        """The next ``unit/{u}/state`` message (a new ``seq``), or None without a position.

        Args:
            t: the sender's wall-clock time of the position, if wanted on the wire.
        """
        if self.position is None:
            return None
        self.seq += 1
        return UnitState(
            position=self.position,
            t=t,
            seq=self.seq,
            kind=UnitKind.MANNED,
            speed_mps=round(self.speed_mps, 6),
            heading_deg=self.heading_deg,
            mobility=ON_FOOT,
        )

    def goal_to_send(self, now: float) -> Goal | None:
        """The configured goal, when it is due: at first, then every ``goal_retry_s``
        until a direction shows the planner acts on it (a later cancel is respected)."""
        g = self.goal
        if g is None or self._goal_acked or not self.connected:
            return None
        if self._goal_sent_s is not None and now - self._goal_sent_s < self.settings.goal_retry_s:
            return None
        self._goal_sent_s = now
        return Goal(position=g)

    def eta_speed_mps(self) -> float:
        """The speed the ETA assumes, and the one the screen shows beside it.

        A simulated walk moves at ``speed_mps * speed_up``; with a GPS it is the
        measured ground speed once moving, else the configured walking speed.
        """
        if not self.settings.gps:
            return self.settings.speed_mps * self.settings.speed_up
        return self.speed_mps if self.speed_mps >= MOVING_MPS else self.settings.speed_mps

    def view(self, now: float, arrow_size: tuple[int, int] = (15, 7)) -> View:
        """What to show at ``now``; ``arrow_size`` is ``(width, height)`` in cells."""
        d = self.direction
        bearing = d.heading_deg if d is not None and d.status in _MOVING else None
        if bearing is None and d is not None and d.status in _MOVING:
            bearing = compass_deg(*d.vector)
        status = STATUS_LABELS[d.status] if d is not None else WAITING_LABEL
        level = d.threat_level if d is not None else 0.0
        fraction = min(level / self.settings.threat_full_scale, 1.0)
        severity = (
            Severity.DANGER
            if fraction >= DANGER_FRACTION
            else Severity.CAUTION
            if fraction >= CAUTION_FRACTION
            else Severity.LOW
        )
        distance = d.distance_to_goal if d is not None else None
        along = d.route_left_m if d is not None and d.route_left_m is not None else distance
        if distance is not None and d is not None and d.status in _MOVING:
            distance = max(distance - self._walked_m, 0.0)
            along = None if along is None else max(along - self._walked_m, 0.0)
        return View(
            status_label=status,
            bearing_deg=bearing,
            bearing=bearing_text(bearing),
            arrow=arrow_art(bearing, *arrow_size, status=d.status.value if d is not None else ""),
            distance_m=distance,
            eta_s=eta_s(along, self.eta_speed_mps()),  # along the route, once the planner has one
            threat_level=level,
            threat_fraction=fraction,
            severity=severity,
            age_s=None if self.last_update_s is None else now - self.last_update_s,
            stale=self.stale(now),
            position=self.position,
            heading_deg=self.heading_deg,
            speed_mps=self.speed_mps,
            walking=self.walking,
            note=self.origin_note or self.link_note or self.note,
            why=why_text(d),
        )
