"""A unit's mobility class on its state, and each member's own under a team's goal (issue 32).

The ground is ``test_world_mobility``'s mesa, whose walls climb 22 degrees:
crossable on foot (30), a barrier on wheels (17), crossable tracked (31).  A
state's class is the unit's standing class, kept until a state names another;
a goal's own class overrides it for that goal.
"""

from __future__ import annotations

import json

import msgspec
import pytest

from pfp_service.core import PlannerParams
from pfp_service.errors import InputError
from pfp_service.terrain.live import of_grid
from pfp_service.wire import Goal, GoalMobility, RejectedEvent, UnitState, encode
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.kinds import BY_NAME, decode_state
from pfp_service.world.world import (
    GoalSet,
    InputRejected,
    StateReported,
    TeamPut,
    World,
    WorldSettings,
)
from tests.unit.test_world_mobility import ON_THE_WALL, _mesa

pytestmark = pytest.mark.unit

START = (0.0, -2000.0)


@pytest.fixture(scope="module")
def ground():
    return of_grid(_mesa(), "foot")  # the planner's class: foot


def _world(ground=None) -> World:
    return World(WorldSettings(planner=PlannerParams(), deliberation="inline", terrain=ground, lookahead=0))


def _state(xy=START, seq=1, kind: str | None = None, slope: float | None = None) -> UnitState:
    mob = None if kind is None else GoalMobility(kind=kind, max_slope_deg=slope)
    return UnitState(position=xy, seq=seq, mobility=mob)


def _status(out, uid: str) -> tuple[str, str]:
    (d,) = [d for d in out.directions if d.unit == uid]
    return d.status.value, d.reason or ""


def test_a_states_class_plans_the_unit_round_its_own_barriers_and_a_goals_class_overrides_it(ground):
    w = _world(ground)
    starts = {"truck": "wheeled", "soldier": "foot", "tank": "tracked", "told_to_walk": "wheeled"}
    w.apply(
        [StateReported(u, _state((40.0 * k, -2000.0), kind=c)) for k, (u, c) in enumerate(starts.items())],
        0.0,
    )
    goals = {u: Goal(position=ON_THE_WALL) for u in starts}
    goals["told_to_walk"] = Goal(position=ON_THE_WALL, mobility=GoalMobility(kind="foot"))  # the goal's wins
    out = w.apply([GoalSet(u, g) for u, g in goals.items()], 0.0)
    status, reason = _status(out, "truck")
    assert status == "trapped" and "slope>17deg" in reason
    for uid in ("soldier", "tank", "told_to_walk"):
        assert _status(out, uid)[0] == "en_route", uid
    assert any(z.startswith("slope>17deg") for z in w.view("truck").zones.ids)  # its preview too
    assert not any(z.startswith("slope>") for z in w.view("told_to_walk").zones.ids)
    # a state without a class keeps the one named before; a new goal without one falls back to it
    w.apply([StateReported("truck", _state(seq=2))], 1.0)
    assert w.records.units["truck"].mobility == GoalMobility(kind="wheeled")
    out = w.apply([GoalSet("told_to_walk", Goal(position=ON_THE_WALL))], 1.0)
    assert _status(out, "told_to_walk")[0] == "trapped"


def test_a_class_changed_mid_route_replans_the_unit_at_once(ground):
    w = _world(ground)
    w.apply([StateReported("u", _state(kind="wheeled"))], 0.0)
    out = w.apply([GoalSet("u", Goal(position=ON_THE_WALL))], 0.0)
    assert _status(out, "u")[0] == "trapped"
    stepper = w.records.units["u"].stepper
    assert stepper is not None
    version = stepper.version
    out = w.apply([StateReported("u", _state(seq=2, kind="wheeled"))], 1.0)  # the same class: nothing redone
    assert stepper.version == version and _status(out, "u")[0] == "trapped"
    out = w.apply([StateReported("u", _state(seq=3, kind="tracked"))], 2.0)  # now it climbs 31 degrees
    assert stepper.version == version + 1 and _status(out, "u")[0] == "en_route"
    out = w.apply([StateReported("u", _state(seq=4, kind="tracked", slope=31.4))], 3.0)  # planned at 31 still
    assert stepper.version == version + 1 and _status(out, "u")[0] == "en_route"
    # planned at 31 still, but seen at a soldier's 1.8 m instead of a vehicle's 2.5: judged afresh
    out = w.apply([StateReported("u", _state(seq=5, kind="foot", slope=31.0))], 4.0)
    assert stepper.version == version + 2 and _status(out, "u")[0] == "en_route"
    out = w.apply([StateReported("u", _state(seq=6, kind="foot", slope=20.0))], 5.0)  # planned at 17: trapped
    assert stepper.version == version + 3 and _status(out, "u")[0] == "trapped"


def test_a_class_changes_nothing_without_terrain():
    w = _world()
    w.apply([StateReported("u", _state(kind="wheeled"))], 0.0)
    out = w.apply([GoalSet("u", Goal(position=ON_THE_WALL))], 0.0)
    assert _status(out, "u")[0] == "en_route"


def test_a_team_goal_plans_each_member_with_its_own_class(ground):
    w = _world(ground)
    classes = {"rifle": "foot", "truck": "wheeled", "tank": "tracked"}
    w.apply(
        [StateReported(u, _state((60.0 * k, -2000.0), kind=c)) for k, (u, c) in enumerate(classes.items())],
        0.0,
    )
    team = TeamUpdate(
        members=list(classes),
        goal=Goal(position=ON_THE_WALL),
        offsets={"truck": (0.0, 10.0), "tank": (0.0, -10.0)},
    )
    out = w.apply([TeamPut("alpha", team)], 0.0)
    assert _status(out, "rifle")[0] == "en_route"
    assert _status(out, "tank")[0] == "en_route"
    status, reason = _status(out, "truck")
    assert status == "trapped" and "slope>17deg" in reason
    # a team's goal naming a class overrides each member's, as a goal does
    wheeled = msgspec.structs.replace(
        team, goal=Goal(position=ON_THE_WALL, mobility=GoalMobility(kind="wheeled"))
    )
    out = w.apply([TeamPut("alpha", wheeled)], 1.0)
    assert {_status(out, u)[0] for u in classes} == {"trapped"}


def test_a_state_naming_an_unknown_class_is_refused_on_its_field_and_the_others_carry_on(ground):
    body = {"position": [0.0, -2000.0], "seq": 1, "mobility": {"class": "hovercraft"}}
    with pytest.raises(InputError) as err:
        decode_state(json.dumps(body).encode(), None, None)
    assert err.value.path == "$.mobility.class" and "hovercraft" in str(err.value)
    for bad, path in (
        ({"class": "foot", "max_slope_deg": 10}, "$.mobility.max_slope_deg"),  # below every class limit
        ({"class": "foot", "max_slope_deg": 90}, "$.mobility.max_slope_deg"),
        ({"class": "Foot!"}, "$.mobility.class"),
        ({"max_slope_deg": 20}, "$.mobility"),
    ):
        with pytest.raises(InputError) as err:
            decode_state(json.dumps({**body, "mobility": bad}).encode(), None, None)
        assert err.value.path.startswith(path), (bad, err.value.path)
    assert BY_NAME["unit state"].decode is decode_state  # the node's rings decode with it
    ok = decode_state(encode(_state(kind="tracked")), None, None)
    assert ok.mobility == GoalMobility(kind="tracked")
    assert decode_state(encode(_state()), None, None).mobility is None
    # the node turns the refusal into an input: rejected on the state's key, the other units steered
    w = _world(ground)
    w.apply([StateReported("good", _state())], 0.0)
    w.apply([GoalSet("good", Goal(position=ON_THE_WALL))], 0.0)
    key = BY_NAME["unit state"].key_of(w.settings.mission, "bad")
    refusal = InputError("$.mobility.class", "unknown mobility class 'hovercraft'")
    out = w.apply(
        [InputRejected(key, refusal, BY_NAME["unit state"].key), StateReported("good", _state(seq=2))], 1.0
    )
    (rej,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert rej.key == key and rej.field == "$.mobility.class"
    assert _status(out, "good")[0] == "en_route"
    # a state put in-process with an unknown class is no class: the planner's
    out = w.apply(
        [StateReported("good", UnitState(position=START, seq=3, mobility=GoalMobility(kind="hovercraft")))],
        2.0,
    )
    assert _status(out, "good")[0] == "en_route"


def test_a_team_goal_naming_an_unknown_class_is_refused_whole_on_its_field():
    team = BY_NAME["team"]
    body = {"members": ["a", "b"], "goal": {"position": [0.0, 0.0], "mobility": {"class": "hovercraft"}}}
    with pytest.raises(InputError) as err:
        team.decode(json.dumps(body).encode(), None, None)
    assert err.value.path == "$.goal.mobility.class" and "hovercraft" in err.value.reason
    body["goal"]["mobility"] = {"class": "foot", "max_slope_deg": 10}
    with pytest.raises(InputError) as err:
        team.decode(json.dumps(body).encode(), None, None)
    assert err.value.path == "$.goal.mobility.max_slope_deg"
    body["goal"]["mobility"] = {"class": "tracked"}
    assert team.decode(json.dumps(body).encode(), None, None).goal.mobility == GoalMobility(kind="tracked")


def test_a_team_preview_replays_each_member_with_its_class(ground):
    import time

    from pfp_service.wire.messages import TeamPreviewRequest
    from pfp_service.world import team_preview

    w = _world(ground)
    classes = {"rifle": "foot", "tank": "tracked"}
    w.apply(
        [
            StateReported(
                u,
                UnitState(position=(60.0 * k, -2000.0), seq=1, speed_mps=5.0, mobility=GoalMobility(kind=c)),
            )
            for k, (u, c) in enumerate(classes.items())
        ],
        0.0,
    )
    team = TeamUpdate(members=list(classes), goal=Goal(position=ON_THE_WALL), offsets={"tank": (0.0, 10.0)})
    w.apply([TeamPut("alpha", team)], 0.0)
    seed = team_preview.seed(w, "alpha", 0.0)
    assert seed is not None
    assert {m.unit: m.mobility for m in seed.members} == {u: GoalMobility(kind=c) for u, c in classes.items()}
    got = team_preview.replay(seed, TeamPreviewRequest(horizon_s=5.0, dt_s=1.0), time.monotonic, 60.0)
    assert {m.unit: m.statuses[0].status.value for m in got.members} == {
        "rifle": "en_route",
        "tank": "en_route",
    }
