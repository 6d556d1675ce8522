"""``pfp fleet`` against a real planner subprocess, and its sans-I/O parts (team files, simulated units)."""

from __future__ import annotations

import io
import json
import queue
import re
import threading
import uuid

import pytest
import zenoh
from pfp_clients.sim import SimUnit

from pfp_service.errors import InputError
from pfp_service.team import UnitSpec, generate_team, load_team
from pfp_service.wire import GOAL_CANCELLED, Direction, DirectionStatus, decode_unit_state, encode, keys
from tests.conftest import run_pfp
from tests.zenoh_util import Inbox, client, planner_process, put_json

TEAM = """\
name: mixed
units:
  - {id: m1, kind: manned, start: [0, 0], goal: [20, 18], speed_mps: 1.4}
  - {id: r1, kind: unmanned, start: [0, 6], goal: [22, 4], speed_mps: 3.0}
  - {id: r2, kind: unmanned, start: [2, 14], goal: [21, 20], speed_mps: 2.5}
"""


@pytest.fixture
def mission():
    return "f" + uuid.uuid4().hex[:10]


@pytest.mark.proc
def test_fleet_reaches_its_goals_around_a_threat(tmp_path, mission):
    team = tmp_path / "team.yaml"
    team.write_text(TEAM)
    with planner_process(mission=mission) as (endpoint, _), client(endpoint) as s:
        put_json(
            s,
            keys.threat(mission, "t1"),
            {"position": [10, 9], "facing_deg": 225, "sigma_range": 2.0, "sigma_lateral": 1.5},
        )
        arrived = Inbox(s, keys.event(mission, "arrived"))
        alive: queue.Queue[tuple[str, bool]] = queue.Queue()
        s.liveliness().declare_subscriber(
            keys.alive_units(mission),
            lambda smp: alive.put((keys.parse(str(smp.key_expr)).id, smp.kind == zenoh.SampleKind.PUT)),
        )
        r = run_pfp(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission,
            "--speed-up", "20", "--until-arrived", "--duration-s", "120", "--progress-s", "0.3", timeout=60,
        )  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
        # no terminal: a progress line every --progress-s, and the last one says where it ended
        progress = re.findall(r"3 units: (\d+) en route, (\d+) arrived, (\d+) trapped, (\d+) stale", r.stdout)
        assert len(progress) >= 2 and progress[-1] == ("0", "3", "0", "0"), r.stdout
        # the planner said so, for every unit: the fleet claims nothing of its own
        seen = {arrived.get(timeout=5)["unit"] for _ in range(3)}
        assert seen == {"m1", "r1", "r2"}
        for uid in ("m1", "r1", "r2"):
            assert f"{uid} arrived at" in r.stdout
        assert "all arrived" in r.stdout
        tokens = []
        while not alive.empty():
            tokens.append(alive.get_nowait())
        assert {u for u, up in tokens if up} == {"m1", "r1", "r2"}
        assert {u for u, up in tokens if not up} == {"m1", "r1", "r2"}  # withdrawn at exit


@pytest.mark.proc
def test_fleet_without_planner_answers_stops_at_duration_and_says_so(mission):
    with planner_process(mission=mission) as (endpoint, _):
        r = run_pfp(
            "fleet", "--generate", "2", "--seed", "4", "--connect", endpoint, "--mission", "nobody-" + mission[:8],
            "--speed-up", "20", "--duration-s", "80", "--until-arrived", timeout=60,
        )  # fmt: skip
    assert r.returncode == 1  # asked to arrive, and nobody guided it
    assert "no direction from any planner" in r.stdout
    assert "arrived " not in r.stdout.split("fleet stops")[0]


@pytest.mark.proc
def test_bad_team_file_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "team.yaml"
    bad.write_text("units:\n  - {id: u1, start: [0, 0]}\n  - {id: u2, start: [1, 1], speed_mps: -3}\n")
    r = run_pfp("fleet", "--team", str(bad), "--connect", "tcp/127.0.0.1:1", timeout=30)
    assert r.returncode == 2
    assert r.stderr.strip() == "pfp fleet: team.yaml line 3, units[1].speed_mps: must be > 0"


@pytest.mark.unit
def test_generated_team_is_seeded_and_mixed():
    a, b = generate_team(6, 7, 100.0), generate_team(6, 7, 100.0)
    assert a == b and a != generate_team(6, 8, 100.0)
    kinds = {u.kind.value for u in a.units}
    assert kinds == {"manned", "unmanned"}
    with pytest.raises(InputError):
        generate_team(3, 0, -1.0)


@pytest.mark.unit
def test_example_team_files_load():
    from pfp_clients.script import load_script

    from tests.conftest import EXAMPLES

    for path in EXAMPLES.glob("*team*.yaml"):
        if path.name.endswith("-inject.yaml"):  # an injection script beside its team file
            assert load_script(path).timeline
        else:
            assert load_team(path).units


def _d(status: DirectionStatus, seq: int, vector=(1.0, 0.0), dist=10.0) -> Direction:
    return Direction(unit="u", seq=seq, status=status, vector=vector, distance_to_goal=dist)


@pytest.mark.unit
def test_sim_unit_moves_only_when_told_and_arrives_only_when_the_planner_says():
    u = SimUnit(UnitSpec(id="u", start=(0.0, 0.0), goal=(10.0, 0.0), speed_mps=2.0))
    assert u.state(0.0).seq == 1
    u.advance(0.5, 0.5, 0.0)
    assert u.position == (0.0, 0.0)  # no direction yet: stays put
    u.on_direction(_d(DirectionStatus.EN_ROUTE, 1), 0.5)
    u.advance(0.5, 1.0, 0.0)
    assert u.position == (1.0, 0.0)
    u.on_direction(_d(DirectionStatus.EN_ROUTE, 2, dist=0.3), 1.0)
    u.advance(0.5, 1.5, 0.0)
    assert u.position == pytest.approx((1.3, 0.0))  # never past the goal
    assert not u.arrived  # close is not arrived: only the planner's word counts
    assert u.on_direction(_d(DirectionStatus.EN_ROUTE, 1), 1.5) is None  # stale seq ignored
    line = u.on_direction(_d(DirectionStatus.TRAPPED, 3, vector=(0.0, 0.0)), 2.0)
    assert line is not None and "trapped" in line
    u.advance(0.5, 2.0, 0.0)
    assert u.position == pytest.approx((1.3, 0.0)) and not u.arrived
    u.on_direction(_d(DirectionStatus.ARRIVED, 4, vector=(0.0, 0.0), dist=0.05), 2.5)
    assert u.arrived and u.arrived_at_s == 2.5


@pytest.mark.unit
def test_progress_is_a_bar_on_a_terminal_and_a_line_every_few_seconds_otherwise():
    from pfp_clients.progress import Progress

    now = [0.0]
    pipe = io.StringIO()
    with Progress(every_s=5.0, stream=pipe, total=3, clock=lambda: now[0], live=False) as p:
        for t in range(12):
            now[0] = float(t)
            p.update(f"summary {t}", t // 4)
        p.say("m1 arrived")
    assert pipe.getvalue().splitlines() == [
        "summary 0",
        "summary 5",
        "summary 10",
        "m1 arrived",
        "summary 11",
    ]
    tty = io.StringIO()
    with Progress(stream=tty, total=3, live=True) as p:
        p.update("2 en route, 1 arrived", 1)
        p.say("r1 arrived at (1, 2)")
    out = tty.getvalue()
    assert "r1 arrived at (1, 2)" in out and "2 en route, 1 arrived" in out and "1/3" in out


@pytest.mark.proc
def test_generate_is_capped_with_a_clear_error():
    r = run_pfp("fleet", "--generate", "100000000", timeout=30)
    assert r.returncode == 2 and r.stderr.strip() == (
        "pfp fleet: error: argument --generate: at most 10000 units per fleet process, "
        "got '100000000' (run several fleets instead)"
    )


# -- the team's origin against the planner's ----------------------------------------------
ORIGIN_TEAM = """\
name: elsewhere
origin: {lat: 50.01, lon: 8.0}
units:
  - {id: o1, start: [0, 0], goal: [6, 0], speed_mps: 1.0}
"""


@pytest.mark.unit
def test_a_team_origin_other_than_the_planners_is_converted_exactly():
    from pfp_clients.fleet import in_planner_frame

    from pfp_service.geo import Origin
    from pfp_service.team import Team

    mine, theirs = Origin(lat=50.01, lon=8.0), Origin(lat=50.0, lon=8.0)
    team = Team(origin=mine, units=[UnitSpec(id="a", start=(0.0, 0.0), goal=(6.0, 0.0))])
    moved, line = in_planner_frame(team, theirs, "m")
    assert line is not None and "50.01,8" in line and "50,8" in line
    x, y = moved.units[0].start
    assert abs(x) < 1e-6 and 1111.0 < y < 1113.0  # 0.01 degree north
    goal = moved.units[0].goal
    assert goal is not None
    for p, q in ((moved.units[0].start, (0.0, 0.0)), (goal, (6.0, 0.0))):
        lat, lon = theirs.to_geodetic(*p)  # the same point on the earth as the team file meant
        back = mine.to_local(lat, lon)
        assert abs(back[0] - q[0]) < 1e-6 and abs(back[1] - q[1]) < 1e-6
    assert in_planner_frame(team, mine, "m") == (team, None)


@pytest.mark.unit
def test_a_team_origin_against_a_planner_without_one_is_refused_naming_both():
    from pfp_clients.fleet import in_planner_frame

    from pfp_service.geo import Origin
    from pfp_service.team import Team

    team = Team(origin=Origin(lat=50.01, lon=8.0), units=[UnitSpec(id="a", start=(0.0, 0.0))])
    with pytest.raises(InputError) as err:
        in_planner_frame(team, None, "m")
    assert "50.01,8" in str(err.value) and "has none" in str(err.value)


def _unit(endpoint: str, mission: str, unit: str) -> dict | None:
    import json

    with client(endpoint) as s:
        for r in s.get(keys.worlds(mission), timeout=2.0):
            if r.ok is not None:
                for u in json.loads(r.ok.payload.to_bytes()).get("units", []):
                    if u["id"] == unit:
                        return u
    return None


@pytest.mark.proc
def test_a_fleet_whose_origin_differs_from_the_planners_is_converted_never_shifted(tmp_path, mission):
    from pfp_service.geo import Origin

    team = tmp_path / "team.yaml"
    team.write_text(ORIGIN_TEAM)
    with planner_process("--origin", "50.0,8.0", "--state-dir", "none", mission=mission) as (endpoint, _):
        r = run_pfp(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission, "--duration-s", "1",
            timeout=90,
        )  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
        assert "differs from the planner's 50,8" in r.stdout, r.stdout
        u = _unit(endpoint, mission, "o1")
    assert u is not None
    planner, mine = Origin(lat=50.0, lon=8.0), Origin(lat=50.01, lon=8.0)
    gx, gy = planner.to_local(*mine.to_geodetic(6.0, 0.0))
    assert abs(u["goal"][0] - gx) < 1e-6 and abs(u["goal"][1] - gy) < 1e-6, u
    sx, sy = planner.to_local(*mine.to_geodetic(0.0, 0.0))
    assert abs(u["position"][0] - sx) <= 1.5 and abs(u["position"][1] - sy) <= 1.5, u  # it moved <= 1 m


@pytest.mark.proc
def test_a_fleet_with_an_origin_against_a_planner_without_one_is_one_line_exit_2(tmp_path, mission):
    team = tmp_path / "team.yaml"
    team.write_text(ORIGIN_TEAM)
    with planner_process("--state-dir", "none", mission=mission) as (endpoint, _):
        r = run_pfp("fleet", "--team", str(team), "--connect", endpoint, "--mission", mission, timeout=90)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    line = r.stderr.strip()
    assert len(line.splitlines()) == 1 and "50.01,8" in line and "has none" in line, line


@pytest.mark.proc
@pytest.mark.parametrize(
    ("reason", "put_again"), [("", True), (GOAL_CANCELLED, False), ("goal refused: x", False)]
)
def test_the_fleet_puts_a_goal_again_only_on_a_no_goal_that_says_nothing(
    mission, tmp_path, reason, put_again
):
    """A planner that lost a goal (restarted) says ``no_goal`` and nothing more: the fleet puts it again,
    the goal last put on the wire (here an operator's, not the team file's). One that says why
    (cancelled: it saw a delete whose own sample may reach the fleet later; refused) is left be.
    A hand-driven planner answers every state so; no delete is ever put."""
    team = tmp_path / "team.yaml"
    team.write_text("units:\n  - {id: a1, kind: unmanned, start: [0, 0], goal: [30, 0], speed_mps: 1.0}\n")
    with planner_process(mission="router-" + mission) as (endpoint, _), client(endpoint) as s:
        goals: queue.Queue[tuple[str, list[float] | None]] = queue.Queue()

        def seen(smp: zenoh.Sample) -> None:
            put = smp.kind == zenoh.SampleKind.PUT
            goals.put((str(smp.kind), json.loads(smp.payload.to_bytes())["position"] if put else None))

        goal_sub = s.declare_subscriber(keys.goals(mission), seen)
        operator_put = threading.Event()

        def answer(smp: zenoh.Sample) -> None:
            st = decode_unit_state(smp.payload.to_bytes())
            if (
                not operator_put.is_set()
            ):  # before the first answer, on the same link: the fleet sees it first
                operator_put.set()
                put_json(s, keys.unit_goal(mission, "a1"), {"position": [12, 9]})
            d = Direction(
                unit="a1", seq=st.seq, status=DirectionStatus.NO_GOAL, vector=(0.0, 0.0), reason=reason
            )
            s.put(keys.unit_direction(mission, "a1"), encode(d))

        state_sub = s.declare_subscriber(keys.sharded_states(mission), answer)
        r = run_pfp(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission, "--duration-s", "5",
            timeout=60,
        )  # fmt: skip
        state_sub.undeclare()
        goal_sub.undeclare()
    puts = [goals.get_nowait() for _ in range(goals.qsize())]
    assert r.returncode in (0, 1), r.stdout + r.stderr
    assert puts[:2] == [("SampleKind.PUT", [30, 0]), ("SampleKind.PUT", [12, 9])], (
        puts
    )  # the file's, the operator's
    again = puts[2:]
    assert bool(again) is put_again and ("goal put again" in r.stdout) is put_again, (puts, r.stdout)
    assert all(p == ("SampleKind.PUT", [12, 9]) for p in again), puts


@pytest.mark.proc
@pytest.mark.parametrize("deliberating", [True, False])
def test_the_fleet_runs_at_real_time_while_a_route_is_deliberated(mission, tmp_path, deliberating):
    """At ``--speed-up 20`` three simulated seconds take 0.15 s of wall time, unless a unit's direction says a
    route is being computed off the planner's loop: then they take three, as they would a real vehicle,
    so a search's wall time is never twenty times the driving. A hand-driven planner answers every state."""
    team = tmp_path / "team.yaml"
    team.write_text("units:\n  - {id: a1, kind: unmanned, start: [0, 0], goal: [300, 0], speed_mps: 1.0}\n")
    with planner_process(mission="router-" + mission) as (endpoint, _), client(endpoint) as s:

        def answer(smp: zenoh.Sample) -> None:
            st = decode_unit_state(smp.payload.to_bytes())
            d = Direction(
                unit="a1", seq=st.seq, status=DirectionStatus.EN_ROUTE, vector=(1.0, 0.0), reach_m=5.0,
                deliberating=deliberating,
            )  # fmt: skip
            s.put(keys.unit_direction(mission, "a1"), encode(d))

        state_sub = s.declare_subscriber(keys.sharded_states(mission), answer)
        r = run_pfp(
            "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission, "--duration-s", "3",
            "--speed-up", "20", "--no-goals", timeout=60,
        )  # fmt: skip
        state_sub.undeclare()
    assert r.returncode in (0, 1), r.stdout + r.stderr
    stop = re.search(r"fleet stops: .*\((\d+) ticks in ([\d.]+) s wall(; (\d+) at real time)?", r.stdout)
    assert stop is not None, r.stdout
    ticks, wall, real = int(stop.group(1)), float(stop.group(2)), int(stop.group(4) or 0)
    if deliberating:
        assert real == ticks - 1 and wall >= 2.7, r.stdout  # the first tick is paced before any answer came
    else:
        assert real == 0 and wall < 2.7, r.stdout
