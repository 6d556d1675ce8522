"""``pfp report`` for teams: the closest pair of each team's members and its robots' link outages with their
cause, from a mission record written and read back as ``pfp record`` writes it."""

from __future__ import annotations

import pytest
from pfp_clients.record.mcapfile import Entry, MissionWriter, read_record
from pfp_clients.record.report import write_report
from pfp_clients.record.report_teams import link_outages, min_separation

from pfp_service.wire import UnitState, encode, keys
from pfp_service.wire.messages import TeamUpdate

pytestmark = pytest.mark.unit

M = "m1"
S = 1_000_000_000
TEAM = TeamUpdate(controller="c", robots=["r"], members=["x"], radio_range_m=50.0, separation_m=5.0)


def _tracks() -> dict[str, list[tuple[float, float, float]]]:
    """c still at the origin; r out to 80 m and back (out of its 50 m range from 6 s to 14 s); x at 3 m from c."""
    r = [(float(t), float(10 * t if t <= 8 else 160 - 10 * t), 0.0) for t in range(17)]
    return {
        "c": [(float(t), 0.0, 0.0) for t in range(17)],
        "r": r,
        "x": [(float(t), 0.0, 3.0) for t in range(17)],
    }


def test_separation_and_outages_on_tracks() -> None:
    tracks = _tracks()
    assert min_separation(tracks, ["c", "r", "x"]) == (0.0, "c-r")  # r starts on c
    assert min_separation(tracks, ["c", "x"]) == (3.0, "c-x")
    (out,) = link_outages(tracks, TEAM)
    assert (out.robot, out.start_s, out.end_s) == ("r", 6.0, 11.0)
    assert out.cause == "range: 80 m from c, radio range 50 m"


def test_the_report_of_a_record_gives_each_team_its_table_and_its_outages(tmp_path) -> None:
    entries = [Entry(0, keys.team(M, "alpha"), encode(TEAM))]
    for u, track in _tracks().items():
        entries += [
            Entry(int(t * S) + 1, keys.unit_state(M, u), encode(UnitState(position=(x, y))))
            for t, x, y in track
        ]
    path = tmp_path / "m.mcap"
    with path.open("wb") as f:
        w = MissionWriter(f, M, None, 0)
        for e in sorted(entries, key=lambda e: e.t_ns):
            assert e.data is not None
            w.put(e.key, e.data, e.t_ns)
        w.finish()
    said: list[str] = []
    written = write_report(read_record(path), tmp_path / "m", say=said.append)
    assert tmp_path / "m.teams.csv" in written
    rows = (tmp_path / "m.teams.csv").read_text().splitlines()
    assert rows[0].startswith("team,members,min sep m,pair,asked m,link outages")
    assert rows[1] == "alpha,x c r,0.00,c-r,5,1,5.0,5.0", rows
    assert any(
        line.strip() == "r out of link 6.0-11.0 s: range: 80 m from c, radio range 50 m" for line in said
    ), said
