"""Seeded scenarios over the Jacksboro DEM: threats on ridges and in valleys between a start and a goal.

Each scenario is about 5-7 km from start to goal, round the DEM's centre (the
plane's origin), with two to four threats placed near the straight line's
middle third, each on the highest or the lowest ground of a patch around a
random point (a ridge or a valley), facing the line.
"""

from __future__ import annotations

import math

import numpy as np

from pfp_service.core import Scheduled, Threat
from pfp_service.terrain.grid import TerrainGrid


def scenario(
    grid: TerrainGrid, seed: int
) -> tuple[tuple[float, float], tuple[float, float], list[Scheduled]]:
    """``(start, goal, schedule)`` for ``seed``, on ``grid`` (planner metres about the DEM's centre)."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.0, 2.0 * math.pi)
    half = rng.uniform(2500.0, 3500.0)
    c, s = math.cos(angle), math.sin(angle)
    start, goal = (-half * c, -half * s), (half * c, half * s)
    threats = []
    for k in range(int(rng.integers(2, 5))):
        along = rng.uniform(-0.35, 0.35) * 2.0 * half
        side = rng.uniform(-1500.0, 1500.0)
        px, py = along * c - side * s, along * s + side * c
        # a ridge (the patch's highest point) or a valley (its lowest) within 400 m
        xs = px + np.linspace(-400.0, 400.0, 17)
        ys = py + np.linspace(-400.0, 400.0, 17)
        gx, gy = np.meshgrid(xs, ys)
        z = grid.elevation(gx.ravel(), gy.ravel())
        pick = int(np.nanargmax(z)) if k % 2 == 0 else int(np.nanargmin(z))
        tx, ty = float(gx.ravel()[pick]), float(gy.ravel()[pick])
        # facing the line: towards its nearest point
        foot = (tx * c + ty * s) * np.array([c, s])
        facing = math.degrees(math.atan2(foot[0] - tx, foot[1] - ty)) % 360.0
        sr = float(rng.uniform(500.0, 900.0))
        threats.append(
            Scheduled(
                Threat.from_facing(
                    (tx, ty), facing, sr, 0.8 * sr, float(rng.uniform(0.0, 2.0)), 1.0, f"t{k + 1}"
                ),
                0,
            )
        )
    return start, goal, threats
