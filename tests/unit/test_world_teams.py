"""Teams in the live world: put and dissolved as inputs, clashes rejected on their key, and the roles' verdicts on
the directions, checked on simulated tracks against shapely (lead's standoff, the cleared corridor, the link)."""

from __future__ import annotations

import math

import pytest
import shapely

from pfp_service.core import PlannerParams
from pfp_service.wire import Direction, Goal, RejectedEvent, ThreatUpdate, UnitState
from pfp_service.wire.messages import TeamUpdate
from pfp_service.world.world import (
    GoalSet,
    StateReported,
    TeamPut,
    TeamRemoved,
    ThreatPut,
    World,
    WorldSettings,
)

pytestmark = pytest.mark.unit

TEAM = TeamUpdate(
    lead="r1",
    follow=["m1"],
    standoff_m=30.0,
    corridor_m=6.0,
    controller="m1",
    robots=["r1"],
    radio_range_m=60.0,
)


def _world() -> World:
    return World(WorldSettings(planner=PlannerParams(intensity="density", step=0.5)))


def _report(uid: str, at: tuple[float, float], speed: float) -> StateReported:
    return StateReported(uid, UnitState(position=at, speed_mps=speed))


def _drive(
    w: World,
    start: dict[str, tuple[float, float]],
    goal: dict[str, tuple[float, float]],
    speed: dict[str, float],
    seconds: float,
    dt: float = 0.5,
    events: list[tuple[float, object]] | None = None,
) -> tuple[dict[str, list[tuple[float, float]]], list[Direction]]:
    """Units that drive along their last direction at their speed, no further than its reach, reporting every ``dt``."""
    at = dict(start)
    tracks = {u: [p] for u, p in at.items()}
    w.apply([_report(u, p, 0.0) for u, p in at.items()], 0.0)
    out = w.apply([GoalSet(u, Goal(position=g, tolerance=1.0)) for u, g in goal.items()], 0.0)
    last = {d.unit: d for d in out.directions}
    said: list[Direction] = list(out.directions)
    pending = sorted(events or [], key=lambda e: e[0])
    t = 0.0
    while t < seconds:
        t += dt
        moved = {}
        for u, p in at.items():
            d = last.get(u)
            run = 0.0 if d is None or d.reach_m is None else min(speed[u] * dt, d.reach_m)
            v = d.vector if d is not None else (0.0, 0.0)
            at[u] = (p[0] + v[0] * run, p[1] + v[1] * run)
            moved[u] = run / dt
            tracks[u].append(at[u])
        inputs: list[object] = [e for tt, e in pending if tt <= t]
        pending = [(tt, e) for tt, e in pending if tt > t]
        out = w.apply([*inputs, *(_report(u, p, moved[u]) for u, p in at.items())], t)  # type: ignore[list-item]
        last.update({d.unit: d for d in out.directions})
        said += out.directions
    return tracks, said


def test_a_team_put_and_dissolved_retells_its_units_and_a_clash_is_rejected_on_its_key() -> None:
    w = _world()
    w.apply([_report(u, (float(i) * 10.0, 0.0), 0.0) for i, u in enumerate(["m1", "r1", "m2", "x"])], 0.0)
    w.apply([GoalSet(u, Goal(position=(500.0, 0.0))) for u in ["m1", "r1", "m2", "x"]], 0.0)
    out = w.apply([TeamPut("alpha", TEAM)], 1.0)
    assert {d.unit for d in out.directions} == {"m1", "r1"}
    clash = TeamUpdate(lead="m1", follow=["m2"])  # m1 follows r1 in alpha: it cannot lead here too
    out = w.apply([TeamPut("bravo", clash), _report("x", (30.0, 0.0), 1.0)], 2.0)
    (rej,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert rej.key == "mumt/default/team/bravo" and rej.field == "$.lead"
    assert "'m1' is already in team 'alpha'" in rej.reason
    assert [d.unit for d in out.directions] == ["x"]  # every other unit carries on
    assert list(w.teams.teams) == ["alpha"]
    out = w.apply([TeamRemoved("alpha")], 3.0)
    assert {d.unit for d in out.directions} == {"m1", "r1"} and not w.teams.teams
    assert all(not d.reason.startswith("team ") for d in out.directions)


def test_lead_follow_and_link_on_simulated_tracks_with_a_threat_mid_route() -> None:
    w = _world()
    w.apply([TeamPut("alpha", TEAM)], 0.0)
    # on the follower's way, behind the lead: the follower's own route would swerve 12 m round it
    bad = ThreatUpdate(
        position=(115.0, -3.0), facing_deg=270.0, sigma_range=10.0, sigma_lateral=6.0, skew=2.0, weight=20.0
    )
    threat = ThreatPut("t1", bad)
    tracks, said = _drive(
        w,
        start={"r1": (6.0, 0.0), "m1": (0.0, 0.0)},
        goal={"r1": (260.0, 0.0), "m1": (240.0, 0.0)},
        speed={"r1": 3.0, "m1": 2.0},
        seconds=200.0,
        events=[(45.0, threat)],
    )
    lead, main = tracks["r1"], tracks["m1"]
    assert math.dist(main[-1], (240.0, 0.0)) < 2.0, main[-1]  # the follower arrived
    # the follower, once in the corridor, never leaves it: checked on the tracks, not the book's
    cleared = shapely.LineString(lead).buffer(3.0 + 0.05)
    first = next(i for i, p in enumerate(main) if cleared.contains(shapely.Point(p)))
    outside = [p for p in main[first:] if not cleared.contains(shapely.Point(p))]
    assert first <= 8 and outside == [], outside[:3]
    assert {"along", "kept"} <= _said(said, "m1")  # the corridor did hold the follower in
    # the link: never beyond radio range
    assert max(math.dist(a, b) for a, b in zip(lead, main)) <= 60.0 + 0.5
    # the standoff: along the follower's way, the lead within +-25 % of 30 m while both move
    moving = [
        abs(lead[i][0] - main[i][0])
        for i in range(40, len(main) - 1)
        if main[i] != main[i + 1] and math.dist(main[i], (240.0, 0.0)) > 40.0
    ]
    kept = sum(22.5 <= d <= 37.5 for d in moving) / len(moving)
    assert kept >= 0.9, kept
    assert {"leading", "at"} <= _said(said, "r1")


def _said(directions: list[Direction], unit: str) -> set[str]:
    """The first word of each team reason given to ``unit``."""
    return {
        d.reason.split(": ", 1)[1].split(" ")[0]
        for d in directions
        if d.unit == unit and d.reason.startswith("team ")
    }


def test_a_robot_whose_controller_stops_holds_at_once_and_says_why() -> None:
    w = _world()
    w.apply([TeamPut("alpha", TeamUpdate(controller="m1", robots=["r1"], radio_range_m=500.0))], 0.0)
    w.apply([_report("m1", (0.0, 0.0), 1.0), _report("r1", (10.0, 0.0), 1.0)], 0.0)
    out = w.apply([GoalSet("r1", Goal(position=(200.0, 0.0)))], 0.0)
    assert out.directions[0].vector != (0.0, 0.0)
    out = w.apply([_report("m1", (0.0, 0.0), 0.0), _report("r1", (11.0, 0.0), 1.0)], 1.0)
    (d,) = [d for d in out.directions if d.unit == "r1"]
    assert d.vector == (0.0, 0.0) and d.reach_m == 0.0
    assert d.reason == "team alpha: lost link: controller m1 has stopped"
    out = w.apply([_report("m1", (1.0, 0.0), 1.0), _report("r1", (11.0, 0.0), 0.0)], 2.0)
    (d,) = [d for d in out.directions if d.unit == "r1"]
    assert d.vector != (0.0, 0.0)  # it moves again


def test_the_world_snapshot_lists_teams_with_their_notes_and_a_peer_takes_them() -> None:
    from pfp_service.cli.status import snapshot_lines
    from pfp_service.wire import decode_world_snapshot, encode
    from pfp_service.world.kinds import inputs_from_snapshot

    w = _world()
    w.apply([TeamPut("alpha", TeamUpdate(controller="m1", robots=["r1"], members=["x"]))], 0.0)
    w.apply([_report("m1", (0.0, 0.0), 0.0), _report("r1", (10.0, 0.0), 1.0)], 0.0)
    w.apply([GoalSet("r1", Goal(position=(200.0, 0.0)))], 0.0)
    snap = decode_world_snapshot(encode(w.snapshot(1.0)))
    (t,) = snap.teams
    assert snap.teams_total == 1 and t.id == "alpha" and t.team.robots == ["r1"]
    assert t.notes == ["r1: team alpha: lost link: controller m1 has stopped"]
    text = "\n".join(snapshot_lines(snap))
    assert "1 teams" in text.splitlines()[0]
    assert any(line.split()[:6] == ["alpha", "-", "-", "m1", "r1", "x"] for line in text.splitlines()), text
    assert "  alpha: r1: team alpha: lost link: controller m1 has stopped" in text
    assert not w.snapshot(1.0, units_from="m1").teams  # on the first page only
    peer = _world()
    peer.apply(inputs_from_snapshot(snap, "other"), 2.0)
    assert peer.teams.teams == {"alpha": t.team}


def test_a_team_is_stored_restored_and_counted_in_the_restored_event(tmp_path) -> None:
    from pfp_service.node.store import Store

    store = Store(tmp_path)
    try:
        store.commit_inputs(
            [TeamPut("alpha", TEAM), TeamPut("bravo", TeamUpdate(members=["x"]))], 1000.0, None
        )
        store.commit_inputs([TeamRemoved("bravo")], 1001.0, None)
        back = store.restore(2000.0)
        assert back.inputs == [TeamPut("alpha", TEAM)] and back.kept["team"] == 1
    finally:
        store.close()


@pytest.mark.parametrize("seed", range(8))
def test_seeded_threats_mid_route_never_take_the_follower_off_cleared_ground(seed: int) -> None:
    """A threat of seeded place, weight and time appears on the way: corridor, link and standoff still hold."""
    import random

    rng = random.Random(seed)
    w = _world()
    w.apply([TeamPut("alpha", TEAM)], 0.0)
    where = (rng.uniform(80, 160), rng.uniform(-6, 6))
    bad = ThreatUpdate(
        position=where,
        facing_deg=270.0,
        sigma_range=10.0,
        sigma_lateral=6.0,
        skew=2.0,
        weight=rng.uniform(10, 30),
    )
    tracks, _said = _drive(
        w,
        start={"r1": (6.0, 0.0), "m1": (0.0, 0.0)},
        goal={"r1": (260.0, 0.0), "m1": (240.0, 0.0)},
        speed={"r1": 3.0, "m1": 2.0},
        seconds=220.0,
        events=[(rng.uniform(30, 60), ThreatPut("t1", bad))],
    )
    lead, main = tracks["r1"], tracks["m1"]
    assert math.dist(main[-1], (240.0, 0.0)) < 1.0, f"seed {seed}: {main[-1]}"
    cleared = shapely.LineString(lead).buffer(3.0 + 0.05)
    first = next(i for i, p in enumerate(main) if cleared.contains(shapely.Point(p)))
    assert [p for p in main[first:] if not cleared.contains(shapely.Point(p))] == [], f"seed {seed}"
    assert max(math.dist(a, b) for a, b in zip(lead, main)) <= 60.0, f"seed {seed}"
    gaps = [
        abs(lead[i][0] - main[i][0])
        for i in range(40, len(main) - 1)
        if main[i] != main[i + 1] and math.dist(main[i], (240.0, 0.0)) > 40.0
    ]
    assert sum(22.5 <= g <= 37.5 for g in gaps) >= 0.9 * len(gaps), f"seed {seed}"


def test_a_follower_waits_for_a_lead_that_has_not_moved_yet_and_says_so() -> None:
    w = _world()
    w.apply([TeamPut("alpha", TeamUpdate(lead="r1", follow=["m1"], corridor_m=6.0))], 0.0)
    w.apply([_report("m1", (0.0, 0.0), 0.0), _report("r1", (1.0, 0.0), 0.0)], 0.0)
    out = w.apply([GoalSet(u, Goal(position=(200.0, 0.0))) for u in ("m1", "r1")], 0.0)
    (d,) = [d for d in out.directions if d.unit == "m1"]
    assert d.vector == (0.0, 0.0) and d.reason == "team alpha: holding: lead r1 has not moved yet"
