"""Real vehicles (``core.tracking``, ``service.progress``): guidance that holds whatever a vehicle does between reports.

Vehicles report at their own rate, drive at their own speed, stop, and their
fix jitters; none of them ever gives a ``step``.  In process the vehicles are
``bench.vehicles``' (written from the wire contract alone) against the
service's own ``World``; the ``proc`` test runs ``pfp fleet`` against a real
``pfp serve``.
"""

from __future__ import annotations

import math
import re
import uuid

import numpy as np
import pytest

from benchmarks import vehicles
from pfp_service.core import tracking
from pfp_service.wire import DirectionStatus, Goal, Progress, UnitState
from pfp_service.world.events import GoalSet, StateReported
from pfp_service.world.progress import ProgressWatch
from pfp_service.world.world import World, WorldSettings
from tests.conftest import run_pfp
from tests.zenoh_util import planner_process

STOPS = ((20.0, 12.0), (60.0, 25.0))


@pytest.mark.unit
def test_simplify_keeps_the_ends_and_no_point_strays_past_the_tolerance():
    t = np.linspace(0.0, math.pi, 400)
    path = np.stack([100.0 * np.cos(t), 100.0 * np.sin(t)], axis=1)
    corners = tracking.simplify(path, 0.5)
    assert 2 < len(corners) < 60
    assert tuple(corners[0]) == tuple(path[0]) and tuple(corners[-1]) == tuple(path[-1])
    for p in path:  # every point within the tolerance of some leg
        d = min(_to_segment(p, a, b) for a, b in zip(corners[:-1], corners[1:]))
        assert d <= 0.5 + 1e-9
    line = np.stack([np.linspace(0, 10, 50), np.zeros(50)], axis=1)
    assert len(tracking.simplify(line, 0.01)) == 2


def _to_segment(p, a, b) -> float:
    ab, ap = b - a, p - a
    u = float(np.clip(np.dot(ap, ab) / max(np.dot(ab, ab), 1e-300), 0.0, 1.0))
    return float(np.hypot(*(ap - u * ab)))


@pytest.mark.unit
def test_the_lead_grows_with_speed_within_its_bounds():
    assert tracking.lead_points(4.0, 0.0) == tracking.LEAD_STEPS
    assert tracking.lead_points(4.0, float("nan")) == tracking.LEAD_STEPS
    assert tracking.lead_points(4.0, 8.0) == 6  # 3 s of 8 m/s, in 4 m points
    assert tracking.lead_points(0.01, 1e6) == tracking.MAX_LEAD_POINTS


@pytest.mark.unit
def test_the_progress_watch_says_holding_and_stalled_as_what_they_are():
    w = ProgressWatch()
    assert w.report(0.0, 0.0, 0.0, 100.0, 5.0, told_to_move=True) is Progress.UNKNOWN
    for k in range(1, 6):  # moving 5 m/s, reported each second, no speed sent
        assert w.report(5.0 * k, 0.0, None, 100.0 + k, None, told_to_move=True) is Progress.MOVING
    assert math.isclose(w.speed_mps, 5.0)
    assert w.report(25.0, 0.0, None, 106.0, 0.0, told_to_move=True) is Progress.HOLDING
    verdicts = [w.report(25.0 + 0.5 * (k % 2), 0.0, None, 107.0 + k, None, True) for k in range(12)]
    assert verdicts[0] is Progress.MOVING and verdicts[-1] is Progress.STALLED  # 10 s within 2 m
    assert w.report(25.0, 0.0, None, 120.0, None, told_to_move=False) is Progress.UNKNOWN
    # a silence says nothing of its speed: measured over fixes that follow one another only
    w2 = ProgressWatch()
    for k in range(4):
        w2.report(2.0 * k, 0.0, None, float(k), None, True)
    w2.report(6.0, 0.0, None, 1000.0, None, True)
    assert math.isclose(w2.speed_mps, 2.0)


@pytest.mark.unit
def test_a_vehicle_standing_still_in_an_empty_world_is_holding_or_stalled_never_escaping_or_trapped():
    w = World(WorldSettings(deliberation="deferred"))
    out = w.apply(
        [
            StateReported("v", UnitState(position=(0.0, 0.0), t=0.0)),
            GoalSet("v", Goal(position=(3000.0, 0.0))),
        ],
        0.0,
    )
    w.apply([job.run(0.0) for job in out.jobs], 0.0)
    said = []
    for k in range(1, 200):  # 15 s at 10 Hz, not moving an inch; then 5 s saying it is stopped
        speed = 0.0 if k >= 150 else None
        out = w.apply(
            [StateReported("v", UnitState(position=(0.0, 0.0), t=0.1 * k, seq=k, speed_mps=speed))], 0.1 * k
        )
        (d,) = [d for d in out.directions if d.unit == "v"]
        assert d.status is DirectionStatus.EN_ROUTE and d.route == "descent", d
        said.append(d.progress)
    assert said[90] is Progress.MOVING and said[148] is Progress.STALLED  # 10 s told to move, not moving
    assert set(said[149:]) == {Progress.HOLDING}


@pytest.mark.unit
@pytest.mark.parametrize("rate,speed", [(0.5, 15.0), (2.0, 4.0), (20.0, 1.0)])
def test_open_ground_any_rate_and_speed_with_stops_and_noise_never_escapes_and_arrives_on_time(rate, speed):
    o = vehicles._drive_one("open", rate, speed, STOPS, seed=3)
    assert o.escaping == 0 and o.trapped == 0, o
    assert o.arrived_s is not None and o.arrived_s <= 1.2 * o.nominal_s, o


@pytest.mark.unit
def test_threats_with_no_trap_are_driven_as_previewed_at_every_rate_and_speed():
    runs = [
        vehicles._drive_one("threats", r, s, STOPS, seed=5) for r, s in [(0.5, 15.0), (2.0, 4.0), (20.0, 1.5)]
    ]
    for o in runs:
        assert o.arrived_s is not None and o.trapped == 0, o
        assert o.exposure <= 1.2 * o.preview_exposure, o
    driven = [o.exposure for o in runs]
    assert max(driven) <= 1.2 * min(driven), driven


TEAM = """\
name: real
units:
  - {id: walker, kind: manned, start: [0, 0], goal: [400, 300], speed_mps: 1.5, rate_hz: 1, gps_sigma_m: 3}
  - {id: ugv, kind: unmanned, start: [0, 50], goal: [600, 450], speed_mps: 8, rate_hz: 2,
     stops: [{at_s: 10, for_s: 12}]}
  - {id: fast, kind: unmanned, start: [0, 100], goal: [900, 100], speed_mps: 15, rate_hz: 20, gps_sigma_m: 3}
"""


@pytest.mark.proc
def test_pfp_fleet_vehicles_of_their_own_rates_speeds_stops_and_noise_arrive_in_open_ground(tmp_path):
    mission = "rv" + uuid.uuid4().hex[:8]
    team = tmp_path / "team.yaml"
    team.write_text(TEAM)
    with planner_process(mission=mission) as (endpoint, _):
        r = run_pfp(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission,
            "--speed-up", "20", "--until-arrived", "--duration-s", "600", "--progress-s", "1", timeout=120,
        )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    assert "escaping" not in r.stdout and "trapped" not in r.stdout.replace("0 trapped", ""), r.stdout
    times = {
        m[0]: float(m[1]) for m in re.findall(r"^(\w+)\s+\w+\s+[\d.]+\s+arrived\s+([\d.]+) s", r.stdout, re.M)
    }
    assert set(times) == {"walker", "ugv", "fast"}, r.stdout
    straight = {"walker": 500 / 1.5, "ugv": 721.1 / 8 + 12, "fast": 900 / 15}
    for uid, t in times.items():
        assert t <= 1.2 * straight[uid] + 2.0, (uid, t, straight[uid])


@pytest.mark.unit
def test_the_handheld_and_the_map_say_why_in_words():
    from pfp_clients.handheld_model import why_text
    from pfp_clients.map.model import MapModel
    from pfp_clients.map.samples import DirectionSeen

    from pfp_service.wire import Direction, RouteKind

    d = Direction(
        unit="u",
        status=DirectionStatus.ESCAPING,
        vector=(1.0, 0.0),
        reason="route round a trap ahead: global (trapped foreseen)",
        route=RouteKind.AROUND_TRAP,
        progress=Progress.STALLED,
    )
    assert why_text(d) == "route round a trap ahead: global (trapped foreseen); no progress seen for 10 s"
    assert why_text(None) == ""
    m = MapModel()
    m.apply([DirectionSeen("u", d)], now=1.0)
    delta = m.take_delta(1.0)
    assert delta is not None
    view = delta["units"]["u"]
    assert view["route"] == "around_trap" and view["progress"] == "stalled"


@pytest.mark.unit
def test_before_its_route_lands_a_unit_may_drive_along_its_predicted_descent_not_one_step():
    w = World(WorldSettings(deliberation="deferred", lookahead=5))
    out = w.apply(
        [StateReported("v", UnitState(position=(0.0, 0.0))), GoalSet("v", Goal(position=(3000.0, 0.0)))], 0.0
    )
    (d,) = [d for d in out.directions if d.unit == "v"]
    step = w.view("v").stepper.params.step
    assert d.deliberating and d.route == "" and out.jobs
    assert d.reach_m is not None and d.reach_m > 4.0 * step  # the five predicted steps lie on its line


@pytest.mark.unit
def test_a_routes_length_left_goes_on_the_wire_and_the_handheld_eta_follows_it():
    from pfp_clients.handheld_model import HandheldModel, Settings

    from pfp_service.wire import Direction

    w = World(WorldSettings(deliberation="deferred"))
    out = w.apply(
        [StateReported("v", UnitState(position=(0.0, 0.0))), GoalSet("v", Goal(position=(900.0, 1200.0)))],
        0.0,
    )
    w.apply([job.run(0.0) for job in out.jobs], 0.0)
    out = w.apply([StateReported("v", UnitState(position=(0.0, 0.0), seq=1))], 1.0)
    (d,) = [d for d in out.directions if d.unit == "v"]
    assert d.route == "descent" and d.route_left_m == pytest.approx(1500.0, rel=1e-3)  # open ground: straight
    m = HandheldModel(Settings(unit="h", speed_mps=1.5, walk=False), (0.0, 0.0), 0.0)
    m.on_direction(
        Direction(
            unit="h",
            status=DirectionStatus.EN_ROUTE,
            vector=(1.0, 0.0),
            distance_to_goal=100.0,
            route_left_m=300.0,
        ),
        0.0,
    )
    assert m.view(0.0).eta_s == pytest.approx(200.0)  # 300 m along the route at 1.5 m/s, not 100 m straight
    m.on_direction(
        Direction(unit="h", status=DirectionStatus.EN_ROUTE, vector=(1.0, 0.0), distance_to_goal=100.0), 0.0
    )
    assert m.view(0.0).eta_s == pytest.approx(100.0 / 1.5)  # no route yet: straight
