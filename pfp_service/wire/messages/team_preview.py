"""A team preview on the wire (``mumt/{m}/preview/team/{t}``): the request's bounds and the members' tracks over time.

The reply is what the live world would drive: each member's positions with
their times, when its status (or what its roles say of it) changed, when it
arrived, and the team's ETA, its slowest member's (``world.team_preview``).
"""

from __future__ import annotations

from typing import Annotated

from msgspec import Meta

from pfp_service.constraints import Id
from pfp_service.wire.messages.structs import DirectionStatus, _Message

__all__ = [
    "MAX_PREVIEW_MEMBERS",
    "MAX_PREVIEW_OUTSIDERS",
    "MAX_REPLAY_HORIZON_S",
    "MemberTrack",
    "StatusChange",
    "TeamPreview",
    "TeamPreviewRequest",
]

MAX_PREVIEW_MEMBERS = 64  # members one team preview replays: a platoon's vehicles, each a stepper per step
# units outside the team one team preview replays with it, nearest first (``world.team_outsiders``):
# each is a stepper per step, as a member is, so together at most twice a full team
MAX_PREVIEW_OUTSIDERS = 64
MAX_REPLAY_HORIZON_S = 3600.0  # simulated seconds one team preview may look ahead
Speed = Annotated[float, Meta(gt=0.0, le=1000.0)]


class TeamPreviewRequest(_Message, frozen=True, kw_only=True):
    """Optional body of a query on ``mumt/{m}/preview/team/{t}``.

    Attributes:
        horizon_s: simulated seconds to replay at most (the replay stops sooner once every member
            with a goal has arrived, or at the preview's budget).
        dt_s: the simulated vehicles' report period, seconds (the fleet's ``1 / rate_hz``).
        speeds: metres per second for members that report no speed of their own (a member held at
            the moment reports 0); a member's reported speed comes first, its mobility's own
            ``speed_mps`` (on its goal or state) last.
    """

    horizon_s: Annotated[float, Meta(gt=0.0, le=MAX_REPLAY_HORIZON_S)] = 600.0
    dt_s: Annotated[float, Meta(ge=0.05, le=10.0)] = 0.5
    speeds: Annotated[dict[Id, Speed], Meta(max_length=MAX_PREVIEW_MEMBERS)] = {}


class StatusChange(_Message, frozen=True, kw_only=True):
    """A member's status or reason changed at ``t_s`` (seconds from the preview's start)."""

    t_s: float
    status: DirectionStatus
    reason: str = ""


class MemberTrack(_Message, frozen=True, kw_only=True):
    """One member's replayed track.

    Attributes:
        unit: the member.
        speed_mps: the speed it was simulated at (0: it did not move).
        points: ``[t_s, x, y]``, seconds from the preview's start and metres, from where it is now.
        statuses: each change of its direction's status or reason (numbers in a reason aside).
        arrived_s: when the planner said it arrived; null if it did not within the replay.
    """

    unit: Id
    speed_mps: float = 0.0
    points: list[tuple[float, float, float]] = []
    statuses: list[StatusChange] = []
    arrived_s: float | None = None


class TeamPreview(_Message, frozen=True, kw_only=True):
    """The reply to a team preview: every member's track, and when the team arrives.

    Attributes:
        team: the team's id.
        eta_s: when its slowest member with a goal arrives, seconds from now; null if one does not
            within the replay.
        members: one track per member, in id order.
        simulated_s: how far the replay got.
        stopped: why it stopped: ``arrived`` (every member with a goal), ``horizon`` or ``budget``
            (the preview's time ran out first: the tracks are as far as it got).
        outsiders: the units outside the team replayed with it (their reach comes within dispersion
            distance of a member's), nearest first; empty with dispersion off.
        outsiders_left_out: how many more were that near but not replayed (past
            ``MAX_PREVIEW_OUTSIDERS``).
    """

    team: Id
    eta_s: float | None = None
    members: list[MemberTrack] = []
    simulated_s: float = 0.0
    stopped: str = "arrived"
    outsiders: Annotated[list[Id], Meta(max_length=MAX_PREVIEW_OUTSIDERS)] = []
    outsiders_left_out: int = 0
