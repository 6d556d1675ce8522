"""Bounded visibility windows: a threat reaching far keeps at most ``WINDOW_SIDE`` heights a side, on the safe side."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import Threat, ThreatField, kernels
from pfp_service.core.visibility import reach_box
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.threat_sight import WINDOW_SIDE, TerrainSight, coarsen
from pfp_service.terrain.viewshed import lowest_visible_height

pytestmark = pytest.mark.unit


def _hills(cell_m: float, half_m: float) -> TerrainGrid:
    """Rolling ground with ridges a few hundred metres apart: much of it hidden from any one point."""
    xs = np.arange(-half_m, half_m + cell_m / 2, cell_m)
    gx, gy = np.meshgrid(xs, xs)
    z = 40.0 * np.sin(gx / 310.0) * np.cos(gy / 270.0) + 25.0 * np.sin((gx + 2 * gy) / 530.0)
    return TerrainGrid(-half_m, -half_m, cell_m, z)


def test_a_far_reaching_threats_window_is_bounded_and_never_hides_what_the_fine_one_shows() -> None:
    grid = _hills(10.0, 5000.0)  # 1,001 x 1,001 cells
    threat = Threat.from_facing((130.0, -270.0), 40.0, 780.0, 600.0, 1.0, 1.0, "far")
    sight = TerrainSight(grid, 1.8)
    field = ThreatField([threat], sight=sight)
    row = field.packed[0]
    nx, ny, cell = int(row[kernels.VIS_NX]), int(row[kernels.VIS_NY]), row[kernels.VIS_CELL]
    assert max(nx, ny) <= WINDOW_SIDE and min(nx, ny) > WINDOW_SIDE // 2
    f = round(cell / grid.cell_m)
    assert f > 1 and cell == f * grid.cell_m
    # the fine window, as the sweep gives it over the same cells
    x0, y0 = row[kernels.VIS_X0], row[kernels.VIS_Y0]
    i0, k0 = round((x0 - grid.x0_m) / grid.cell_m), round((y0 - grid.y0_m) / grid.cell_m)
    box = reach_box(field.packed[0])  # the box the sight swept, as it cuts it to the grid
    i1 = min(grid.shape[1] - 1, math.ceil((box[2] - grid.x0_m) / grid.cell_m))
    k1 = min(grid.shape[0] - 1, math.ceil((box[3] - grid.y0_m) / grid.cell_m))
    assert (nx - 2) * f < i1 - i0 <= (nx - 1) * f and (ny - 2) * f < k1 - k0 <= (ny - 1) * f
    oi, ok = round((130.0 - grid.x0_m) / grid.cell_m), round((-270.0 - grid.y0_m) / grid.cell_m)
    fine = lowest_visible_height(
        grid.z[k0 : k1 + 1, i0 : i1 + 1], (ok - k0, oi - i0), 2.0, np.inf, grid.cell_m, grid.cell_m, 0.0
    )
    coarse = row[kernels.VIS_DATA : kernels.VIS_DATA + nx * ny].reshape(ny, nx)
    assert (fine > 1.8).mean() > 0.2  # the ground hides much of it: the check below means something
    r = f // 2
    for k in range(0, ny, 7):
        for i in range(0, nx, 7):
            a, b = k * f, i * f
            block = fine[max(0, a - r) : a + r + 1, max(0, b - r) : b + r + 1]
            if block.size:
                assert coarse[k, i] == np.nanmin(np.nan_to_num(block, nan=0.0)), (k, i)


def test_coarsen_keeps_a_window_that_fits_and_covers_one_that_does_not() -> None:
    low = np.arange(35.0).reshape(5, 7)
    assert coarsen(low, 1) is low
    out = coarsen(low, 3)  # nodes at 0, 3, 6 (and 0, 3, 6 rows past the end: 5 rows -> 3 nodes)
    assert out.shape == (3, 3)
    assert out[1, 1] == low[2:5, 2:5].min()
    assert out[2, 2] == low[4, 5]  # the last node, past the end, the edge's least within a cell
