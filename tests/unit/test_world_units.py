"""A unit's one owner (world/units.py): its records, counts, and phase, and every transition its table allows.

``test_every_transition_the_table_allows_happens_in_a_real_world`` drives a
real ``World`` into each phase and through each step the table lists from it,
and checks that step was taken there (the owner's check records it); a step
the table refuses raises ``PhaseError``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest

from pfp_service.core import PlannerParams, Stepper, resolve
from pfp_service.wire import DirectionStatus, Goal, ThreatUpdate, UnitState
from pfp_service.wire.keys import shard_of
from pfp_service.world.events import Deliberated, Input, Job
from pfp_service.world.ownership import shard_owners
from pfp_service.world.units import GONE, TRANSITIONS, Phase, PhaseError, Started, Step, Units, phase_of
from pfp_service.world.world import (
    GoalCancelled,
    GoalSet,
    MissionRestored,
    PeerPlanner,
    StateReported,
    ThreatPut,
    Tick,
    World,
    WorldSettings,
)

pytestmark = pytest.mark.unit

U = "u"
FAR = Goal(position=(100.0, 100.0))
AWAY = Goal(position=(-100.0, -100.0))
ME = WorldSettings().planner_id
# a peer that, once it joins, guides ``U`` (rendezvous over the two planners' shards)
PEER = next(p for p in (f"p{i}" for i in range(200)) if shard_owners({ME, p})[shard_of(U)] == p)
STALE_S = WorldSettings().unit_stale_s
FORGET_S = WorldSettings().unit_forget_s
DEBOUNCE_S = WorldSettings().liveliness_debounce_s


# -- the records and counts (formerly world_records') ---------------------------------
def _resolved():
    return resolve(PlannerParams(), (0.0, 0.0), (5.0, 5.0), ())


def _guided(book: Units, unit: str = "a") -> Stepper:
    rec = book.add(unit, True, 0.0, reported=True)
    book.reported(rec, (0.0, 0.0), 1, None, 0.0, 0.0)
    book.set_goal(rec, Goal(position=(5.0, 5.0)), None)
    stepper = Stepper((0.0, 0.0), (5.0, 5.0), _resolved())
    book.started(rec, Started((Goal(position=(5.0, 5.0)), (0.0, 0.0), _resolved()), stepper))
    return stepper


def _job(book: Units, unit: str) -> Job:
    rec = book.records[unit]
    job = Job(unit, rec.token(), "foresee", None, None, 0.0)  # type: ignore[arg-type]
    book.asked(rec, job)
    return job


def test_a_unit_made_by_anything_but_a_report_is_stale_until_it_reports():
    book = Units()
    heard, told = book.add("a", True, 0.0, reported=True), book.add("b", True, 0.0, reported=False)
    assert not heard.stale and told.stale and told.stale_since == 0.0 and book.stale == 1
    assert not told.live() and told.phase is Phase.UNKNOWN  # never reported: no position, no direction
    book.reported(told, (1.0, 2.0), 7, "ugv", 3.0, 0.0)
    assert not told.stale and book.stale == 0 and told.live() and told.kind == "ugv" and told.seq == 7
    assert told.phase is Phase.NO_GOAL


def test_stale_and_forgotten_keep_the_count():
    book = Units()
    rec = book.add("a", True, 0.0, reported=True)
    assert not book.go_stale(rec, 1.0)  # never reported where it is: nothing to mark
    book.reported(rec, (0.0, 0.0), 1, None, 1.0, 0.0)
    assert book.go_stale(rec, 5.0) and not book.go_stale(rec, 6.0) and book.stale == 1
    assert rec.phase is Phase.STALE
    book.forget(rec)
    assert book.records == {} and book.stale == 0


def test_a_report_answers_the_push_and_clears_the_token_gone():
    book = Units()
    rec = book.add("a", True, 0.0, reported=True)
    rec.token_gone_since, rec.push = 1.0, object()  # type: ignore[assignment]
    book.reported(rec, (0.0, 0.0), None, None, 2.0, 0.0)
    assert rec.token_gone_since is None and rec.push is None and rec.last_seen == 2.0


def test_dropping_a_mission_starts_an_epoch_and_supersedes_the_job():
    book = Units()
    stepper = _guided(book)
    rec = book.records["a"]
    job = _job(book, "a")
    assert book.deliberating == 1 and rec.token() == (1, stepper.version) and rec.phase is Phase.DELIBERATING
    book.drop_mission(rec)
    assert book.superseded == [job] and not job.cancelled and rec.job is None and book.deliberating == 0
    assert rec.goal is None and rec.stepper is None and rec.last_status is None and rec.last_reason == ""
    assert rec.epoch == 2 and rec.token() == (2, -1) and rec.phase is Phase.NO_GOAL


def test_an_answered_job_is_counted_off_once():
    book = Units()
    _guided(book)
    job = _job(book, "a")
    rec = book.records["a"]
    done = Deliberated("a", job.token, None)
    assert book.deliberated(rec, done).value == "quiet" and book.deliberating == 0
    assert book.deliberated(rec, done).value == "ignored" and book.deliberating == 0
    assert rec.phase is Phase.GUIDED


def test_handing_a_unit_over_keeps_its_mission_not_its_stepper():
    book = Units()
    _guided(book)
    rec = book.records["a"]
    book.hand_over(rec)
    assert not rec.owned and rec.stepper is None and rec.shared is not None and rec.phase is Phase.PEER


# -- the table refuses ----------------------------------------------------------------
def test_a_step_the_table_does_not_allow_is_refused_loudly():
    book = Units()
    rec = book.add("a", True, 0.0, reported=False)  # never heard from: unknown
    with pytest.raises(PhaseError, match="asked from unknown"):
        book.asked(rec, Job("a", rec.token(), "foresee", None, None, 0.0))  # type: ignore[arg-type]
    book.reported(rec, (0.0, 0.0), 1, None, 1.0, 0.0)
    assert rec.phase is Phase.NO_GOAL
    with pytest.raises(PhaseError, match="forgotten from no_goal"):
        book.forget(rec)  # a fresh unit is never forgotten
    assert "a" in book.records and rec.phase is Phase.NO_GOAL
    with pytest.raises(PhaseError, match="taken_over from no_goal"):
        book.take_over(rec)  # it was never another planner's


def test_the_table_names_every_phase_and_step():
    assert {p for p, _ in TRANSITIONS} == set(Phase)
    assert {s for _, s in TRANSITIONS} == set(Step)
    # every phase it can reach is a phase, and only forgetting leaves none
    assert all(to <= set(Phase) and (to or s is Step.FORGOTTEN) for (_, s), to in TRANSITIONS.items())


# -- every transition the table allows, in a real world ---------------------------------
def _state(x: float = 0.0, y: float = 0.0, seq: int | None = None) -> StateReported:
    return StateReported(U, UnitState(position=(x, y), seq=seq))


def _horseshoe() -> list[Input]:
    """Threats in a horseshoe open toward the start (0, 0), the goal behind it at (100, 100)."""
    out: list[Input] = []
    for k in range(9):
        b = math.radians(-55 + 200 * k / 8)
        pos = (60 + 12 * math.sin(b), 60 + 12 * math.cos(b))
        update = ThreatUpdate(position=pos, facing_deg=225, sigma_range=4, sigma_lateral=4, skew=0.5)
        out.append(ThreatPut(f"h{k}", update))
    return out


class At:
    """A world with unit ``U`` in a phase, at time ``t``, and the jobs it was last asked."""

    def __init__(self, world: World, t: float, jobs: list[Job] | None = None) -> None:
        self.world, self.t, self.jobs = world, t, jobs or []

    def apply(self, inputs: list[Input], dt: float = 0.0) -> At:
        self.t += dt
        out = self.world.apply(inputs, self.t)
        self.jobs = out.jobs or self.jobs
        return self

    @property
    def rec(self):  # the unit's record, read only
        return self.world._units.get(U)


def _world(**kw) -> World:
    return World(WorldSettings(cluster=True, **kw))


def unknown() -> At:
    return At(_world(), 0.0).apply([GoalSet(U, FAR)])


def no_goal() -> At:
    return At(_world(), 0.0).apply([_state()])


def guided() -> At:
    return At(_world(), 0.0).apply([_state(), GoalSet(U, FAR)])


def arrived() -> At:
    return At(_world(), 0.0).apply([_state(), GoalSet(U, Goal(position=(0.0, 0.0)))])


def deliberating() -> At:
    w = _world(deliberation="deferred", planner=PlannerParams(escape="auto"))
    return At(w, 0.0).apply([*_horseshoe(), _state(), GoalSet(U, FAR)])


def trapped() -> At:
    at = At(_world(planner=PlannerParams(escape="none")), 0.0).apply(
        [*_horseshoe(), _state(), GoalSet(U, FAR)]
    )
    step = at.world.view(U).stepper.params.step
    pos = (0.0, 0.0)
    for k in range(1, 3000):
        out = at.world.apply([_state(*pos, k)], float(k))
        (d,) = out.directions
        if d.status is DirectionStatus.TRAPPED:
            break
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
    at.t = float(k)
    return at


def stale(build: Callable[[], At] = guided) -> Callable[[], At]:
    def gone_quiet() -> At:
        at = build()
        return at.apply([Tick(at.t + STALE_S + 1.0)], STALE_S + 1.0)

    return gone_quiet


def peer(heard: bool = True) -> Callable[[], At]:
    def build() -> At:
        at = At(_world(), 0.0).apply([PeerPlanner(PEER, True), GoalSet(U, FAR)])
        return at.apply([_state()]) if heard else at

    return build


def _tick(dt: float) -> Callable[[At], list[Input]]:
    return lambda at: [Tick(at.t + dt)]


def _answer(at: At) -> list[Input]:
    (job,) = at.jobs
    return [job.run(at.t)]


REPORT = lambda at: [_state(seq=99)]
SET = lambda at: [GoalSet(U, AWAY)]
CANCEL = lambda at: [GoalCancelled(U)]
RESTORE = lambda at: [
    MissionRestored(U, FAR, (0.0, 0.0), resolve(PlannerParams(), (0.0, 0.0), (100.0, 100.0), ()))
]
THREAT = lambda at: [  # beside the unit, wherever it is
    ThreatPut(
        "near",
        ThreatUpdate(
            position=(at.rec.position[0] + 2, at.rec.position[1] + 2), sigma_range=4, sigma_lateral=4
        ),
    )
]
JOIN = lambda at: [PeerPlanner(PEER, True)]
LEAVE = lambda at: [PeerPlanner(PEER, False), Tick(at.t + DEBOUNCE_S + 1.0)]
STALE = _tick(STALE_S + 1.0)

BUILD: dict[Phase, Callable[[], At]] = {
    Phase.UNKNOWN: unknown,
    Phase.NO_GOAL: no_goal,
    Phase.GUIDED: guided,
    Phase.ARRIVED: arrived,
    Phase.TRAPPED: trapped,
    Phase.DELIBERATING: deliberating,
    Phase.STALE: stale(),
    Phase.PEER: peer(),
}

# (phase, step) -> how to get there (default: ``BUILD[phase]``) and the inputs that take the step
DRIVE: dict[tuple[Phase, Step], tuple[Callable[[], At] | None, Callable[[At], list[Input]]]] = {
    (Phase.UNKNOWN, Step.MADE): (lambda: At(_world(), 0.0), lambda at: [GoalSet(U, FAR)]),
    (Phase.PEER, Step.REPORTED): (peer(heard=False), REPORT),
    (Phase.UNKNOWN, Step.REPORTED): (None, REPORT),
    (Phase.STALE, Step.REPORTED): (None, REPORT),
    **{(p, Step.WENT_STALE): (None, STALE) for p in (Phase.NO_GOAL, Phase.GUIDED, Phase.ARRIVED)},
    **{(p, Step.WENT_STALE): (None, STALE) for p in (Phase.TRAPPED, Phase.DELIBERATING, Phase.PEER)},
    (Phase.UNKNOWN, Step.FORGOTTEN): (None, _tick(FORGET_S + 1.0)),  # type: ignore[operator]
    (Phase.STALE, Step.FORGOTTEN): (None, _tick(FORGET_S + 1.0)),  # type: ignore[operator]
    (Phase.PEER, Step.FORGOTTEN): (stale(peer()), _tick(FORGET_S + 1.0)),  # type: ignore[operator]
    **{(p, Step.GOAL_SET): (None, SET) for p in Phase},
    **{(p, Step.GOAL_DROPPED): (None, CANCEL) for p in Phase if p is not Phase.NO_GOAL},
    (Phase.UNKNOWN, Step.STARTED): (None, RESTORE),
    (Phase.STALE, Step.STARTED): (None, RESTORE),
    (Phase.GUIDED, Step.STARTED): (unknown, REPORT),  # its goal came first: started at its first report
    (Phase.GUIDED, Step.STEERED): (unknown, REPORT),  # its first direction
    (Phase.NO_GOAL, Step.STEERED): (lambda: At(_world(), 0.0), REPORT),
    (Phase.ARRIVED, Step.STEERED): (None, lambda at: [_state(50.0, 0.0)]),  # driven off its goal
    (Phase.TRAPPED, Step.STEERED): (None, REPORT),  # carried out of the trap by hand
    (Phase.DELIBERATING, Step.STEERED): (None, lambda at: [_state(100.0, 100.0)]),  # arrived meanwhile
    (Phase.GUIDED, Step.ASKED): (
        lambda: At(_world(deliberation="deferred"), 0.0).apply(_horseshoe()),
        lambda at: [_state(), GoalSet(U, FAR)],
    ),
    (Phase.DELIBERATING, Step.ANSWERED): (None, _answer),
    (Phase.STALE, Step.ANSWERED): (stale(deliberating), _answer),
    **{(p, Step.WORLD_CHANGED): (None, THREAT) for p in (Phase.GUIDED, Phase.ARRIVED, Phase.TRAPPED)},
    (Phase.STALE, Step.WORLD_CHANGED): (None, THREAT),
    (Phase.DELIBERATING, Step.WORLD_CHANGED): (None, THREAT),
    **{(p, Step.HANDED_OVER): (None, JOIN) for p in Phase if p is not Phase.PEER},
    (Phase.PEER, Step.TAKEN_OVER): (None, LEAVE),
}


def test_every_transition_the_table_allows_has_a_drive():
    assert set(DRIVE) == set(TRANSITIONS)


@pytest.mark.parametrize("pair", sorted(TRANSITIONS, key=lambda k: (k[0].value, k[1].value)), ids=str)
def test_every_transition_the_table_allows_happens_in_a_real_world(pair, monkeypatch):
    phase, _ = pair
    build, inputs = DRIVE[pair]
    at = (build or BUILD[phase])()
    if build is None:  # else it is reached on the way, in the same ``apply``
        assert at.rec is not None and at.rec.phase is phase and phase_of(at.rec) is phase
    taken: list[tuple[Phase, Step, Phase | None]] = []
    to = Units._to

    def seen(self: Units, rec, s: Step, gone: bool = False) -> None:
        before = rec.phase
        to(self, rec, s, gone)
        taken.append((before, s, None if gone else rec.phase))

    monkeypatch.setattr(Units, "_to", seen)
    at.apply(inputs(at), 1.0)
    landed = [after for before, s, after in taken if (before, s) == pair]
    assert landed, f"{pair} not taken; taken: {taken}"
    allowed = TRANSITIONS[pair]
    assert all((a in allowed) if a is not None else allowed == GONE for a in landed)
    if at.rec is not None:  # what the owner recorded is what the fields say
        assert at.rec.phase is phase_of(at.rec)
