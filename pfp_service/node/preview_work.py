"""The preview service's work in its worker processes: one preview or team preview, under an alarm past its budget.

``compute`` walks one unit's preview (``world.preview``), ``compute_team``
replays a team (``world.team_preview``); both run under ``_armed``: an alarm
just past the budget stops any phase that overruns (a route search, a
foresight, a replay's step), dropping the caches it may have left half-built
or, when the alarm surfaced through compiled code, retiring the worker.
"""

from __future__ import annotations

import dataclasses
import signal
import time
from collections.abc import Callable
from typing import Any

from pfp_service import geojson
from pfp_service.errors import DeadlinePassed, InputError
from pfp_service.node.workerproc import forget_fields, retire, world_field, world_threats
from pfp_service.wire import ErrorReply, encode
from pfp_service.world.preview import preview
from pfp_service.world.team_preview import replay
from pfp_service.world.terrain import sight_of
from pfp_service.world.translate import fit_reply

__all__ = ["ALARM_GRACE_S", "TEAM_SHARE", "WALK_SHARE", "compute", "compute_team"]

ALARM_GRACE_S = 0.05  # the worker's alarm stops any phase this long past the budget
WALK_SHARE = 0.5  # of the budget, for the walk; measuring its path may take as long again (``plan``)
TEAM_SHARE = (
    0.8  # of the budget, for a team's replay (checked at every step); encoding its reply takes the rest
)


class _Overrun(BaseException):
    """The worker's alarm: the preview's budget is spent (not an ``Exception``: nothing may swallow it)."""


_ARMED = [False]
_FIRED = [False]


def _alarm(signum: int, frame: Any) -> None:
    if _ARMED[0]:
        _ARMED[0] = False
        _FIRED[0] = True
        raise _Overrun


def compute(job: tuple[Any, ...]) -> tuple[str, bytes]:
    """One preview in a worker: ``("reply", body)`` or ``("error", ErrorReply JSON)``.

    The walk stops itself at half the budget and measuring the path by the
    whole; an alarm just past it stops any other phase (a route search, a
    foresight): the caches it may have left half-built are dropped, or, when
    the alarm surfaced through compiled code, the worker is retired.
    """
    view, request, origin, budget_s, max_iter = job
    threats = world_threats()
    view = dataclasses.replace(view, threats=threats)

    def work() -> tuple[str, bytes]:
        field = world_field(view.settings.planner.intensity, sight_of(view.settings.terrain, view.height_m))
        result = preview(view, request, time.monotonic, WALK_SHARE * budget_s, max_iter, field)
        _ARMED[0] = False
        if request.geojson:
            return "reply", geojson.preview_reply(origin, result, threats, result.path[0], result.path[-1])
        return "reply", fit_reply(result)

    return _armed(budget_s, work)


def compute_team(job: tuple[Any, ...]) -> tuple[str, bytes]:
    """One team preview in a worker (``team_preview.replay``): it stops itself at ``TEAM_SHARE`` of the budget."""
    seed, request, budget_s = job
    return _armed(
        budget_s, lambda: ("reply", encode(replay(seed, request, time.monotonic, TEAM_SHARE * budget_s)))
    )


def _armed(budget_s: float, work: Callable[[], tuple[str, bytes]]) -> tuple[str, bytes]:
    """``work()`` under the worker's alarm, just past ``budget_s``: a refusal or an overrun is an error reply."""
    signal.signal(signal.SIGALRM, _alarm)
    _FIRED[0] = False
    _ARMED[0] = True
    signal.setitimer(signal.ITIMER_REAL, budget_s + ALARM_GRACE_S)
    try:
        return work()
    except InputError as err:
        return "error", encode(ErrorReply.of(err))
    except DeadlinePassed:
        return "error", encode(ErrorReply(error="expired: the preview's budget was spent measuring its path"))
    except BaseException as exc:
        if not _FIRED[0]:
            raise
        if isinstance(exc, _Overrun):  # stopped between two bytecodes of ours: the caches it fed go
            _forget_caches()
        else:  # surfaced through C (numba's dispatcher wraps it in a SystemError): a fresh worker
            retire()
        return "error", encode(ErrorReply(error="expired: the preview's budget was spent and it was stopped"))
    finally:
        _ARMED[0] = False
        signal.setitimer(signal.ITIMER_REAL, 0)


def _forget_caches() -> None:
    """What an interrupted phase may have left half-built: the shared fields and the route cache."""
    from pfp_service.core.routes import ROUTES

    forget_fields()
    ROUTES.clear()
