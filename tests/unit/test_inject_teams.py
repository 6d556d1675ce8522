"""``pfp inject``'s team expectations (keeps_from, only_cleared_by, link_to): read from a script and judged on tracks."""

from __future__ import annotations

import pytest
from pfp_clients.expectations import judge
from pfp_clients.script import Expect, load_script
from pfp_clients.watch import Watch

from pfp_service.errors import InputError
from pfp_service.world.world import TeamPut, ThreatPut, ThreatUpdate
from tests.unit.test_world_teams import TEAM, _drive, _world

pytestmark = pytest.mark.unit


def _watch(tracks: dict[str, list[tuple[float, float]]], dt: float = 0.5) -> Watch:
    w = Watch()
    for unit, track in tracks.items():
        for i, p in enumerate(track):
            w.on_state(unit, p, i * dt)
    return w


def test_the_team_expectations_are_read_from_a_script_and_half_given_is_refused(tmp_path) -> None:
    p = tmp_path / "inject.yaml"
    p.write_text(
        "expect:\n"
        "  - {unit: m1, keeps_from: m2, at_least_m: 5}\n"
        "  - {unit: m1, only_cleared_by: r1, corridor_m: 6}\n"
        "  - {unit: r1, link_to: m1, at_least_pct: 99, radio_range_m: 60}\n"
    )
    got = load_script(p).expect
    assert [e.describe() for e in got] == [
        "m1 keeps at least 5 m from m2",
        "m1 enters only ground r1 cleared (6 m wide)",
        "r1 within 60 m of m1 >= 99 % of the time",
    ]
    p.write_text("expect:\n  - {unit: m1, keeps_from: m2}\n")
    with pytest.raises(InputError) as e:
        load_script(p)
    assert e.value.path == "inject.yaml line 2, expect[0].at_least_m"


def test_keeps_from_and_link_to_judge_the_two_tracks_at_the_same_times() -> None:
    w = _watch({"a": [(float(i), 0.0) for i in range(11)], "b": [(10.0 - i, 3.0) for i in range(11)]})
    v = judge(Expect(unit="a", keeps_from="b", at_least_m=3.0), w)
    assert v.held and v.detail == "closest 3.00 m, at (5.0, 0.0)"
    assert not judge(Expect(unit="a", keeps_from="b", at_least_m=3.5), w).held
    v = judge(Expect(unit="a", link_to="b", at_least_pct=50.0, radio_range_m=5.0), w)
    assert v.detail == "in range 45.5 % of 11 reports (farthest 10.4 m)" and not v.held  # i = 3..7
    assert not judge(Expect(unit="a", keeps_from="zz", at_least_m=1.0), w).held  # never seen: not held


def test_only_cleared_by_takes_ground_crossed_before_not_after() -> None:
    lead = [(float(i), 0.0) for i in range(20)]
    behind = [(max(i - 5.0, 0.0), 0.5) for i in range(20)]
    w = _watch({"r1": lead, "m1": behind})
    v = judge(Expect(unit="m1", only_cleared_by="r1", corridor_m=2.0), w)
    assert v.held, v.detail
    ahead = [(i + 2.0, 0.0) for i in range(20)]  # on the lead's line, but ahead of it: not yet cleared
    v = judge(Expect(unit="m1", only_cleared_by="r1", corridor_m=2.0), _watch({"r1": lead, "m1": ahead}))
    assert not v.held and "never entered" in v.detail
    swerve = [*behind[:10], (5.0, 3.0), *behind[11:]]
    v = judge(Expect(unit="m1", only_cleared_by="r1", corridor_m=2.0), _watch({"r1": lead, "m1": swerve}))
    assert not v.held and v.detail == "outside the cleared corridor at (5.00, 3.00), t=5.0 s, 2.00 m out"


def test_a_simulated_team_meets_its_expectations() -> None:
    w = _world()
    w.apply([TeamPut("alpha", TEAM)], 0.0)
    bad = ThreatUpdate(
        position=(115.0, -3.0), facing_deg=270.0, sigma_range=10.0, sigma_lateral=6.0, weight=20.0
    )
    tracks, _said = _drive(
        w,
        start={"r1": (6.0, 0.0), "m1": (0.0, 0.0)},
        goal={"r1": (260.0, 0.0), "m1": (240.0, 0.0)},
        speed={"r1": 3.0, "m1": 2.0},
        seconds=200.0,
        events=[(45.0, ThreatPut("t1", bad))],
    )
    watch = _watch(tracks)
    for e in (
        Expect(unit="m1", only_cleared_by="r1", corridor_m=6.0 + 0.1),
        Expect(unit="r1", link_to="m1", at_least_pct=99.0, radio_range_m=60.0),
        Expect(unit="m1", keeps_from="r1", at_least_m=1.0),
    ):
        v = judge(e, watch)
        assert v.held, (e.describe(), v.detail)


def test_add_team_is_read_with_the_wire_s_checks_and_a_team_arrival_is_judged_on_its_last_member(
    tmp_path,
) -> None:
    from pfp_clients.script import AddTeam, team_members

    p = tmp_path / "inject.yaml"
    p.write_text(
        "timeline:\n"
        "  - {do: add_team, team: alpha, lead: r1, follow: [m1], controller: m1, robots: [r1],\n"
        "     goal: {position: [240, 0], tolerance: 1}, spacing_m: 8}\n"
        "  - {do: remove_team, team: alpha, at_s: 100}\n"
        "expect:\n"
        "  - {team: alpha, arrives_within_s: 120}\n"
    )
    script = load_script(p)
    (add, _gone) = script.timeline
    assert isinstance(add, AddTeam) and add.update().goal is not None and add.update().spacing_m == 8.0
    assert add.describe() == "add team alpha: r1 m1, its goal (240, 0)"
    assert team_members(script) == {"alpha": ("r1", "m1")}
    assert script.expect[0].describe() == "team alpha arrives within 120 s"
    w = _watch({"r1": [(0.0, 0.0)], "m1": [(0.0, 0.0)]})
    e = script.expect[0]
    v = judge(e, w, teams=team_members(script))
    assert not v.held and v.detail == "r1 not arrived (last status: never heard of)"
    w.on_arrived_event("r1", 80.0)
    w.on_arrived_event("m1", 95.5)
    v = judge(e, w, teams=team_members(script))
    assert v.held and v.detail == "arrived at 95.5 s (the last, m1)"
    w.arrived_at_s["m1"] = 130.0
    assert not judge(e, w, teams=team_members(script)).held
    # a team the wire refuses is refused in the file, naming the field; so is an expectation of a team never added
    p.write_text("timeline:\n  - {do: add_team, team: alpha, lead: r1, follow: [r1]}\n")
    with pytest.raises(InputError) as err:
        load_script(p)
    assert "inject.yaml line 2" in err.value.path and "cannot follow itself" in err.value.reason
    p.write_text("expect:\n  - {team: bravo, arrives_within_s: 10}\n")
    with pytest.raises(InputError) as err:
        load_script(p)
    assert err.value.path == "inject.yaml line 2, expect[0].team"
    p.write_text("expect:\n  - {team: bravo, unit: m1, arrives_within_s: 10}\n")
    with pytest.raises(InputError):
        load_script(p)
