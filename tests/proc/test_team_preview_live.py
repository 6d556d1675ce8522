"""A team preview from a real planner matches the tracks its team then drives live.

A real ``pfp serve`` guides the scout team of ``examples/team-scout.yaml``; the fleet's simulated
vehicles (``pfp_clients.sim.SimUnit``) drive it in lockstep over Zenoh (every unit reports, then
moves on the answers).  Mid-route, ``mumt/{m}/preview/team/alpha`` is asked; the live tracks that
follow must lie within ``TOLERANCE_M`` of the preview's at every time both hold, and the team must
arrive when the preview said.  With dispersion on, a manned unit outside the team crosses the
team's way just after the preview is asked: the preview replays it (``outsiders``), and the tracks
still match.  ``proc``: the planner is a subprocess with its worker processes.
"""

from __future__ import annotations

import json
import math
import queue
from pathlib import Path

import msgspec
import pytest
from pfp_clients.sim import SimUnit

from pfp_service.team import UnitSpec, load_team, team_updates
from pfp_service.wire import Direction, UnitKind, decode, encode, keys
from pfp_service.wire.messages import TeamPreview, TeamPreviewRequest
from tests.zenoh_util import client, planner_process, put_in_force

pytestmark = pytest.mark.proc

M = "teamprev"
DT = 0.5
AT_S = 20.0
# The planner may take one unit's report in one batch and its teammate's in the next, where the
# replay takes both at once: the roles then judge against a teammate one report older.  Half a
# report's travel at the slowest member's 2 m/s, so a replay a report out of step fails.
TOLERANCE_M = 0.5
ROOT = Path(__file__).resolve().parents[2]


# manned and first by id, and slow: the scout gives way to it for seconds where their ways cross, soon
# after the preview is asked (a preview that left it out is 28.8 m off the live tracks, in process)
CROSSING = UnitSpec(id="a1", start=(80.0, -30.0), goal=(80.0, 90.0), speed_mps=1.0, kind=UnitKind.MANNED)
# With it, a right of way or a wait judged a report apart in the planner's batches holds a member a
# report (or a few) longer or shorter than the replay does, and it may stay that far behind: 0.005 to
# 6.5 m off, arriving 0-1.5 s later, in fourteen runs at load 6-9.  Leaving it out would be far worse:
# the team alone arrives 6 s sooner (96 s, not 102 s), some 18 m of the scout's travel.
OUTSIDER_TOLERANCE_M = 8.0
OUTSIDER_ETA_S = 4 * DT


@pytest.mark.parametrize("outsider", [False, True], ids=["team-alone", "outsider-crossing"])
def test_a_team_preview_matches_the_tracks_the_team_then_drives(outsider: bool, tmp_path: Path) -> None:
    team = load_team(ROOT / "examples" / "team-scout.yaml")
    units = [*team.units, CROSSING] if outsider else list(team.units)
    fleet = {u.id: SimUnit(u, rate_hz=1.0 / DT) for u in units}
    extra: tuple[str, ...] = ()
    if outsider:  # on foot: 5 m apart, so the scout and its manned vehicle keep their standoff
        (tmp_path / "pfp.toml").write_text('dispersion = true\ndefault_class = "foot"\n')
        extra = ("--config", str(tmp_path / "pfp.toml"))
    with (
        planner_process("--team-preview-budget-ms", "20000", *extra, mission=M) as (endpoint, _proc),
        client(endpoint) as s,
    ):
        answers: queue.Queue[Direction] = queue.Queue()
        sub = s.declare_subscriber(
            keys.unit_directions(M), lambda smp: answers.put(decode(Direction, smp.payload.to_bytes()))
        )
        ((tid, update),) = team_updates(team)
        put_in_force(s, M, {keys.team(M, tid): msgspec.to_builtins(update)})
        goals = {keys.unit_goal(M, u.id): {"position": list(u.goal or u.start)} for u in units}

        def step(t: float) -> None:
            """Every unit reports at ``t``; each then holds the direction answering its report."""
            seqs = {}
            for u in fleet.values():
                st = u.state(t)
                seqs[u.id] = st.seq
                s.put(keys.unit_state(M, u.id), encode(st))
            waiting = set(fleet)
            while waiting:
                d = answers.get(timeout=20.0)
                if d.unit in waiting and d.seq == seqs[d.unit]:
                    fleet[d.unit].on_direction(d, t)
                    waiting.discard(d.unit)

        step(0.0)
        put_in_force(s, M, goals)
        # refused, naming why: a team not in force, a bad body, a member that has not reported moving
        (nobody,) = s.get(keys.team_preview(M, "nobody"), timeout=20.0)
        assert nobody.err is not None and "no team 'nobody'" in nobody.err.payload.to_string()
        (bad,) = s.get(keys.team_preview(M, "alpha"), payload=b'{"dt_s": 0}', timeout=20.0)
        assert bad.err is not None and json.loads(bad.err.payload.to_bytes())["field"] == "$.dt_s"
        (still,) = s.get(keys.team_preview(M, "alpha"), timeout=20.0)
        assert still.err is not None and json.loads(still.err.payload.to_bytes())["field"] == "$.speeds"
        live: dict[str, dict[float, tuple[float, float]]] = {u: {} for u in fleet}
        t = 0.0
        preview: TeamPreview | None = None
        while t < 400.0 and not all(fleet[u.id].arrived for u in team.units):
            t = round(t + DT, 6)
            for u in fleet.values():
                u.advance(DT, t, 0.0)
            step(t)
            for u in fleet.values():
                live[u.id][t] = u.position
            if t == AT_S:
                got = s.get(
                    keys.team_preview(M, "alpha"),
                    payload=encode(TeamPreviewRequest(horizon_s=300.0)),
                    timeout=60.0,
                )
                replies = [r for r in got]
                assert replies and replies[0].ok is not None, [
                    str(r.err.payload.to_bytes()) for r in replies if r.err
                ]
                preview = decode(TeamPreview, replies[0].ok.payload.to_bytes())
        sub.undeclare()
    assert preview is not None and preview.stopped == "arrived", preview
    assert preview.outsiders == (["a1"] if outsider else []) and preview.outsiders_left_out == 0
    gave_way = [(m.unit, c.reason) for m in preview.members for c in m.statuses if "a1" in c.reason]
    assert bool(gave_way) == outsider, gave_way  # the outsider changed what the team does
    print("gave way:", gave_way[:3])
    gaps = []
    for m in preview.members:
        for tp, x, y in m.points:
            at = live[m.unit].get(round(AT_S + tp, 6))
            if at is not None:
                gaps.append(math.dist((x, y), at))
    tolerance = OUTSIDER_TOLERANCE_M if outsider else TOLERANCE_M
    assert len(gaps) > 100 and max(gaps) <= tolerance, (max(gaps), json.dumps(sorted(gaps)[-5:]))
    print(f"team preview against live: {len(gaps)} points, largest gap {max(gaps):.4f} m")
    arrived = max(fleet[u.id].arrived_at_s or math.nan for u in team.units)
    print(f"ETA: preview {AT_S + (preview.eta_s or math.nan)} s, live {arrived} s")
    late = OUTSIDER_ETA_S if outsider else 2 * DT
    assert preview.eta_s is not None and abs(AT_S + preview.eta_s - arrived) <= late, (
        preview.eta_s,
        arrived,
    )
