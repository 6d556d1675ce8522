"""``pfp bench service --teams``' scene: a march that keeps its separation, and the crowd behind ``--dense``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from benchmarks._layout import layout
from benchmarks._service_teams import SPACING_M, TEAM_SIZE, march, teams
from pfp_service.world.separations import SEPARATION_M

pytestmark = pytest.mark.unit


def _nearest(starts: list[tuple[float, float]]) -> float:
    pts = np.array(starts)
    return float(cKDTree(pts).query(pts, 2)[0][:, 1].min())


def test_the_march_keeps_every_unit_its_separation_and_the_crowd_does_not():
    lay = march(1000, [], 2023)
    assert len(lay["starts"]) == len(lay["goals"]) == 1001  # the bystander last, as the service bench's
    assert _nearest(lay["starts"]) >= SPACING_M - 1e-9 > SEPARATION_M["wheeled"]
    assert _nearest(layout(1000, 0, 2023)["starts"]) < SEPARATION_M["wheeled"]  # the --dense scene


def test_a_march_team_is_a_column_heading_for_goals_as_far_apart_as_its_starts():
    lay = march(64, [], 7)
    made = teams(lay, 64)
    assert len(made) == 64 // TEAM_SIZE
    for k, (group, team) in enumerate(zip(lay["teams"], made.values())):
        ids = [f"u{i}" for i in group]
        assert [team.lead, *team.follow] == ids[:3] and team.robots == [ids[0], ids[3]]
        assert team.controller == ids[1] and team.standoff_m == 2 * SPACING_M
        starts, goals = (
            np.array([lay["starts"][i] for i in group]),
            np.array([lay["goals"][i] for i in group]),
        )
        assert np.all(np.diff(starts[:, 0]) == -SPACING_M)  # lead in front, robot at the rear
        shift = goals - starts
        assert np.allclose(shift, shift[0]) and shift[0, 0] > 1000.0  # the column marches east, whole
        heading = np.degrees(np.arctan2(shift[0, 1], shift[0, 0]))
        assert abs(heading) > 30.0 if k % 8 == 0 else abs(heading) <= 5.0  # one in eight wheels


def test_the_dense_teams_are_neighbours_along_the_edge_with_their_first_figures():
    lay = layout(16, 0, 2023)
    made = teams(lay, 16)
    ys = [lay["starts"][int(made["g0"].lead[1:])][1], lay["starts"][int(made["g3"].lead[1:])][1]]
    assert len(made) == 4 and ys[0] < ys[1]
    assert (made["g0"].standoff_m, made["g0"].corridor_m, made["g0"].radio_range_m) == (40.0, 8.0, 300.0)
