"""A unit's own mobility fields on the wire: its height and flat speed over its class's (issues 32, 33).

``GoalMobility`` on a state or a goal may override ``height_m`` and ``speed_mps``
as a scenario's ``unit:`` block does.  A threat over terrain sees the unit at its
own height; its preview over terrain reckons its ETA at its own speed; a team
preview moves a member that reports no speed at its mobility's; and a
controller's link is judged from the controller's own height to the robot's.
"""

from __future__ import annotations

import json
import math
import time

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pfp_service.core import PlannerParams, ThreatField
from pfp_service.core.mobility import planned_height
from pfp_service.errors import InputError
from pfp_service.team import MobilitySpec
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.live import LiveTerrain, of_grid
from pfp_service.wire import Direction, DirectionStatus, Goal, GoalMobility, UnitState
from pfp_service.wire.messages import TeamPreviewRequest, TeamUpdate
from pfp_service.world import team_preview
from pfp_service.world.kinds import BY_NAME
from pfp_service.world.preview import preview
from pfp_service.world.team_book import TeamBook
from pfp_service.world.terrain import link_sight
from pfp_service.world.units import UnitRecord
from pfp_service.world.world import GoalSet, StateReported, TeamPut, ThreatPut, World, WorldSettings
from tests.unit.test_world_sight_height import EAST, START, THREAT, _ground

pytestmark = pytest.mark.unit

Point = tuple[float, float]


def _world(ground: LiveTerrain | None) -> World:
    return World(WorldSettings(planner=PlannerParams(), deliberation="inline", terrain=ground, lookahead=0))


def _mob(kind: str = "foot", **over: float) -> GoalMobility:
    return GoalMobility(kind=kind, **over)  # type: ignore[arg-type]


# -- the wire ------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["unit state", "goal"])
def test_height_and_speed_decode_on_a_state_and_a_goal_and_out_of_range_is_refused_on_its_field(kind):
    decode = BY_NAME[kind].decode
    body = {"position": [0.0, 0.0], "mobility": {"class": "wheeled", "height_m": 3.5, "speed_mps": 6.0}}
    got = decode(json.dumps(body).encode(), None, None)
    assert got.mobility == GoalMobility(kind="wheeled", height_m=3.5, speed_mps=6.0)
    assert (
        decode(b'{"position": [0, 0], "mobility": {"class": "foot"}}', None, None).mobility.height_m is None
    )
    for field, bad in (
        ("height_m", 0.05),
        ("height_m", 20.5),
        ("height_m", "1e999"),  # not finite
        ("height_m", "tall"),
        ("speed_mps", 0.0),
        ("speed_mps", 41.0),
        ("speed_mps", "-1e999"),
    ):
        text = json.dumps({"position": [0, 0], "mobility": {"class": "foot", field: bad}})
        text = text.replace('"1e999"', "1e999").replace('"-1e999"', "-1e999")
        with pytest.raises(InputError) as err:
            decode(text.encode(), None, None)
        assert err.value.path == f"$.mobility.{field}", (field, bad, err.value)


def test_a_team_goals_override_out_of_range_is_refused_whole_on_its_field():
    body = {
        "members": ["a", "b"],
        "goal": {"position": [0.0, 0.0], "mobility": {"class": "foot", "height_m": 99}},
    }
    with pytest.raises(InputError) as err:
        BY_NAME["team"].decode(json.dumps(body).encode(), None, None)
    assert err.value.path == "$.goal.mobility.height_m"


def test_a_team_files_mobility_carries_its_overrides_onto_the_wire():
    spec = msgspec.convert({"class": "tracked", "height_m": 3.0, "speed_mps": 5.0}, MobilitySpec)
    assert spec.wire() == GoalMobility(kind="tracked", height_m=3.0, speed_mps=5.0)
    with pytest.raises(msgspec.ValidationError, match=r"\$\.speed_mps"):
        msgspec.convert({"class": "tracked", "speed_mps": 50.0}, MobilitySpec)


# -- a threat sees the unit at its own height ------------------------------------------------------
def test_behind_a_crest_a_soldier_with_a_mast_is_seen_where_a_plain_soldier_is_hidden():
    """``test_world_sight_height``'s crest: behind it a threat sees down to 2 m above the plain.  A soldier
    (1.8 m) is hidden; the same soldier with ``height_m`` 3 (a mast) is seen, at the 3 m a window at that
    height gives; one with 2.4 m is seen at 2.5 m (the next quarter metre up, a wheeled vehicle's), its
    field the vehicle's own."""
    w = _world(of_grid(_ground(0.0), "foot"))
    w.apply([ThreatPut("t", THREAT)], 0.0)
    units = {
        "plain": _mob("foot"),
        "mast": _mob("foot", height_m=3.0),
        "near": _mob("foot", height_m=2.4),
        "wheeled": _mob("wheeled"),
    }
    w.apply([StateReported(u, UnitState(position=START, seq=1, mobility=m)) for u, m in units.items()], 0.0)
    w.apply([GoalSet(u, Goal(position=(300.0, 800.0))) for u in units], 0.0)
    blind = float(ThreatField(w.field.threats).level(np.array([EAST]))[0])

    def seen(uid: str) -> float:
        rec = w.records.units[uid]
        return float(w.records.field_for(*w._route(rec)).level(np.array([EAST]))[0]) / blind

    def sigmoid(height_m: float) -> float:  # L = 2 m behind the crest, softness height / 6
        return 1.0 / (1.0 + math.exp(-(height_m - 2.0) / (height_m / 6.0)))

    assert seen("plain") == pytest.approx(sigmoid(1.8), abs=0.05) and seen("plain") < 0.5
    assert seen("mast") == pytest.approx(sigmoid(3.0), abs=0.05) and seen("mast") > 0.85
    heights = {u: w._route(w.records.units[u])[3] for u in ("near", "wheeled")}
    assert heights == {"near": 2.5, "wheeled": 2.5}  # seen as one: the threats' field at 2.5 m serves both
    assert seen("near") == seen("wheeled") == pytest.approx(sigmoid(2.5), abs=0.05)
    assert planned_height(2.4) == 2.5 and planned_height(1.8) == 1.8 and planned_height(3.0) == 3.0


def test_a_state_that_changes_only_the_units_height_rejudges_it():
    w = _world(of_grid(_ground(0.0), "foot"))
    w.apply(
        [ThreatPut("t", THREAT), StateReported("u", UnitState(position=START, seq=1, mobility=_mob()))], 0.0
    )
    w.apply([GoalSet("u", Goal(position=(300.0, 800.0)))], 0.0)
    rec = w.records.units["u"]
    before = w._route(rec)
    out = w.apply([StateReported("u", UnitState(position=START, seq=2, mobility=_mob(height_m=3.0)))], 1.0)
    assert w._route(rec) != before and w._route(rec)[3] == 3.0
    (d,) = [d for d in out.directions if d.unit == "u"]
    assert d.seq == 2


# -- its ETA at its own speed ----------------------------------------------------------------------
def _flat() -> LiveTerrain:
    return of_grid(TerrainGrid(-1000.0, -1000.0, 10.0, np.full((201, 201), 100.0)), "foot")


def test_a_preview_over_terrain_reckons_its_eta_at_the_units_own_speed():
    """Over flat ground a soldier goes at its flat speed: 1.4 m/s by its class, 2.8 with its state's
    override, 0.7 with its goal's (a goal's mobility over its state's)."""
    w = _world(_flat())
    states = {"class": None, "state": _mob(speed_mps=2.8), "goal": _mob(speed_mps=2.8)}
    w.apply(
        [StateReported(u, UnitState(position=(-500.0, 0.0), seq=1, mobility=m)) for u, m in states.items()],
        0.0,
    )
    goals = {u: Goal(position=(500.0, 40.0)) for u in states}
    goals["goal"] = Goal(position=(500.0, 40.0), mobility=_mob(speed_mps=0.7))
    w.apply([GoalSet(u, g) for u, g in goals.items()], 0.0)
    speeds = {"class": 1.4, "state": 2.8, "goal": 0.7}
    for uid, speed in speeds.items():
        got = preview(w.view(uid), None, time.monotonic, 5.0, 10_000)
        assert got.status.value == "reached" and got.length > 900.0
        assert got.eta_s == pytest.approx(got.length / speed, rel=1e-9), uid
        assert got.climb_m == pytest.approx(0.0) and got.path_elevation_m == pytest.approx(
            [100.0] * len(got.path)
        )


def test_a_team_preview_moves_a_member_that_reports_no_speed_at_its_mobilitys_own():
    w = World(WorldSettings(planner=PlannerParams(), deliberation="inline", lookahead=0))
    w.apply([TeamPut("alpha", TeamUpdate(members=["a", "b"]))], 0.0)
    mobs = {"a": _mob(speed_mps=2.0), "b": None}
    w.apply(
        [
            StateReported(u, UnitState(position=(0.0, 30.0 * i), seq=1, mobility=m))
            for i, (u, m) in enumerate(mobs.items())
        ],
        0.0,
    )
    w.apply([GoalSet(u, Goal(position=(100.0, 30.0 * i), tolerance=1.0)) for i, u in enumerate(mobs)], 0.0)
    seeded = team_preview.seed(w, "alpha", 0.0)
    assert seeded is not None
    with pytest.raises(InputError) as err:  # b said no speed anywhere
        team_preview.replay(seeded, None, time.monotonic, 10.0)
    assert err.value.path == "$.speeds" and "b" in err.value.reason and "a," not in err.value.reason
    got = team_preview.replay(seeded, TeamPreviewRequest(speeds={"b": 4.0}), time.monotonic, 30.0)
    arrived = {m.unit: m.arrived_s for m in got.members}
    assert arrived["a"] is not None and arrived["b"] is not None
    assert arrived["a"] == pytest.approx(99.0 / 2.0, abs=2.0) and arrived["b"] == pytest.approx(
        99.0 / 4.0, abs=2.0
    )
    given = team_preview.replay(seeded, TeamPreviewRequest(speeds={"a": 1.0, "b": 4.0}), time.monotonic, 30.0)
    assert {m.unit: m.arrived_s for m in given.members}["a"] == pytest.approx(
        99.0, abs=2.0
    )  # the request's first


# -- the controller's link at each end's own height -------------------------------------------------
def _wall(crest_m: float) -> LiveTerrain:
    """Flat ground at 100 m and a crest ``crest_m`` high along x = 0, one cell wide each side."""
    xs = np.arange(101) * 10.0 - 500.0
    gx, _ = np.meshgrid(xs, xs)
    z = 100.0 + crest_m * np.clip(1.0 - np.abs(gx) / 10.0, 0.0, 1.0)
    return of_grid(TerrainGrid(-500.0, -500.0, 10.0, z), "wheeled")  # the planner's class: 2.5 m


def _dir(unit: str, vector: Point, reach_m: float) -> Direction:
    return Direction(unit=unit, vector=vector, status=DirectionStatus.EN_ROUTE, reach_m=reach_m)


def _units(
    c_mob: GoalMobility | None, r_mob: GoalMobility | None, c_at: Point, r_at: Point
) -> dict[str, UnitRecord]:
    units = {}
    for k, (u, p, m) in enumerate((("m1", c_at, c_mob), ("r1", r_at, r_mob))):
        rec = UnitRecord(u, k, position=p, goal=Goal(position=(p[0], p[1] + 400.0)))
        rec.mobility = m
        units[u] = rec
    return units


@pytest.mark.parametrize(
    ("crest_m", "c_mob", "r_mob", "goes"),
    [
        (3.0, None, None, False),  # the class's 2.5 m at both ends: under the 3 m crest
        (3.0, None, _mob("wheeled", height_m=6.0), True),  # the robot's 6 m mast: 4.25 m over the crest
        (3.0, _mob("foot", height_m=6.0), None, True),  # ... and the controller's
        (3.0, _mob("foot"), _mob("wheeled", height_m=6.0), False),  # a soldier's 1.8 m to 6 m: 3.9 m
        (1.0, None, None, True),  # the class's 2.5 m over a 1 m crest
        (1.0, _mob("foot"), _mob("foot"), False),  # two soldiers' 1.8 m
    ],
)
def test_a_robots_link_is_judged_from_its_controllers_own_height_to_its_own(crest_m, c_mob, r_mob, goes):
    """The robot, across the crest from its controller, steps north along it: the sight line from the
    controller's mast to its own crosses the crest at the masts' mean height, and its step goes where that
    keeps ``teams.SIGHT_CLEARANCE_M`` (1 m) over the crest, whatever the planner's class (wheeled, 2.5 m)."""
    book = TeamBook(link_sight(_wall(crest_m)))
    book.put("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=1500.0))
    units = _units(c_mob, r_mob, (-100.0, 0.0), (100.0, 0.0))
    north, hold = _dir("r1", (0.0, 1.0), 20.0), _dir("m1", (0.0, 0.0), 0.0)
    out = {d.unit: d for d in book.judge([hold, north], units, now=0.0)}
    if goes:
        assert out["r1"] is north, out["r1"].reason
    else:
        assert out["r1"] is not north and "line of sight" in out["r1"].reason, out["r1"].reason


@pytest.mark.parametrize("mast_m", [None, 4.0])
def test_a_controllers_step_keeps_a_robot_it_sees_only_for_the_robots_own_mast(mast_m):
    """The controller walks east toward a 3.2 m crest, its robot beyond it: a 4 m mast is linked from where
    the controller stands (3.25 m over the crest) and lost 87.5 m from it, so the step is cut there; a robot
    at the class's height is out of its sight already, so the step goes on (that robot turns back alone)."""
    book = TeamBook(link_sight(_wall(3.2)))
    book.put("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=1500.0))
    r_mob = None if mast_m is None else _mob("wheeled", height_m=mast_m)
    units = _units(None, r_mob, (-100.0, 0.0), (100.0, 0.0))
    east, hold = _dir("m1", (1.0, 0.0), 80.0), _dir("r1", (0.0, 0.0), 0.0)
    out = {d.unit: d for d in book.judge([east, hold], units, now=0.0)}
    if mast_m is None:
        assert out["m1"] is east
    else:
        d = out["m1"]
        assert d.reach_m is not None and 5.0 <= d.reach_m <= 12.5 and "r1" in d.reason, d  # sampled every 5 m


@pytest.mark.parametrize(("mast_a", "mast_b"), [(1.5, 6.0), (6.0, 1.5), (1.8, 2.5)])
def test_a_sight_line_between_two_masts_agrees_with_the_exact_ray_at_grid_points(mast_a, mast_b):
    """``link_sight.sees`` with an end of each height: seen exactly where Franklin's exact ray from ``a``'s
    eye finds ``b``'s lowest visible height at or under ``b``'s mast (``test_link_sight``'s ridge)."""
    from pfp_service.terrain.link_sight import sees
    from pfp_service.terrain.viewshed import exact_lowest_visible_height
    from tests.unit.test_link_sight import CELL_M, XS, _ridge_grid

    rng, grid = np.random.default_rng(7), _ridge_grid()
    told = {True: 0, False: 0}
    for _ in range(200):
        (r0, c0), (r1, c1) = rng.integers(5, 96, size=(2, 2))
        if (r0, c0) == (r1, c1):
            continue
        low = exact_lowest_visible_height(grid.z, (int(r0), int(c0)), mast_a, np.array([[r1, c1]]), CELL_M)[0]
        if abs(low - mast_b) < 0.5:  # within half a metre of the mast: the two samplings may differ
            continue
        a, b = (float(XS[c0]), float(XS[r0])), (float(XS[c1]), float(XS[r1]))
        assert sees(grid, a, b, mast_a, 0.0, mast_b) == (low <= mast_b), (a, b, low)
        told[bool(low <= mast_b)] += 1
    assert told[True] >= 10 and told[False] >= 10, told  # both answers were asked for


def test_pfp_inject_sends_a_scenarios_unit_overrides_and_refuses_one_the_wire_cannot_carry(tmp_path):
    from pfp_clients.live_scenario import live_scenario

    f = tmp_path / "s.yaml"
    f.write_text("start: [0, 0]\ngoal: [100, 0]\nunit: {class: wheeled, height_m: 3.5, speed_mps: 6}\n")
    (spec,) = live_scenario(f, rate_hz=5.0).team.units
    assert spec.mobility is not None
    assert spec.mobility.wire() == GoalMobility(kind="wheeled", height_m=3.5, speed_mps=6.0)
    f.write_text("start: [0, 0]\ngoal: [100, 0]\nunit: {class: wheeled, height_m: 30}\n")
    with pytest.raises(InputError) as err:
        live_scenario(f)
    assert str(err.value).startswith("s.yaml, unit") and "height_m" in str(err.value)


_WILD = st.one_of(
    st.none(),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -1.0, 0.1, 20.0, 40.0, 1e308]),
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(height=_WILD, speed=_WILD)
def test_an_in_process_override_of_any_float_never_raises_and_is_its_class_past_the_wires_bounds(
    height, speed
):
    """A state put in-process (not decoded: no bounds checked) with any height and speed: the world never raises,
    the unit is guided, its preview's ETA is finite, and an override the wire would refuse counts as none."""
    w = _world(_flat())
    mob = GoalMobility(kind="foot", height_m=height, speed_mps=speed)
    w.apply([StateReported("odd", UnitState(position=(-500.0, 0.0), seq=1, mobility=mob))], 0.0)
    out = w.apply([GoalSet("odd", Goal(position=(500.0, 0.0)))], 0.0)
    assert [d.status.value for d in out.directions] == ["en_route"]
    got = preview(w.view("odd"), None, time.monotonic, 5.0, 10_000)
    wire_ok = speed is not None and 0.1 <= speed <= 40.0
    assert got.eta_s == pytest.approx(got.length / (speed if wire_ok else 1.4), rel=1e-9)
    book = TeamBook(link_sight(_wall(1.0)))
    book.put("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=1500.0))
    units = _units(mob, mob, (-100.0, 0.0), (100.0, 0.0))
    book.judge([_dir("m1", (0.0, 1.0), 20.0), _dir("r1", (0.0, 1.0), 20.0)], units, now=0.0)
