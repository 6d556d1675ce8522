"""A route kept as its legs (``EscapeRun.along``) is the resampled route, point for point and step for step."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from pfp_service.core import steprule
from pfp_service.core.polylines import resample
from pfp_service.core.route import EscapeRun, legs
from pfp_service.core.zones import Zone, ZoneSet

pytestmark = pytest.mark.unit


def _corners(rng: np.random.Generator, k: int) -> np.ndarray:
    return np.cumsum(rng.uniform(-40.0, 40.0, size=(k, 2)), axis=0) + rng.uniform(-1e3, 1e3, size=2)


@pytest.mark.parametrize("seed", range(6))
def test_legs_give_resamples_points_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for k in (2, 3, 7, 25):
        corners = _corners(rng, k)
        step = float(rng.uniform(0.05, 3.0))
        dense = resample(corners, step)
        run = EscapeRun.along("global", corners, step)
        assert run.n == len(dense) and run.limit == 2 * len(dense) + 20
        assert np.array_equal(run.points(), dense)  # exact, not close
        assert run.end() == (float(dense[-1, 0]), float(dense[-1, 1]))


def test_a_route_of_legs_is_far_smaller_than_its_points() -> None:
    corners = np.array([(0.0, 0.0), (600.0, 300.0), (1200.0, 250.0), (1900.0, 900.0)])
    run = EscapeRun.along("global", corners, 1.0)
    dense = EscapeRun("global", resample(corners, 1.0), 1.0)
    assert dense.path.nbytes > 30_000 and run.segs.nbytes + run.path.nbytes < 200
    assert len(pickle.dumps(run)) * 20 < len(pickle.dumps(dense))


def _walk(
    run: EscapeRun, goal: tuple[float, float], x: float, y: float, zones: ZoneSet | None
) -> list[tuple]:
    unit = steprule.unit(goal, 0.0, 0.1, run.step, watch=False)
    out: list[tuple] = []
    for _ in range(4 * run.n):
        ahead = run.ahead(unit, x, y, 12)
        stepped = run.steer(unit, x, y, zones)
        out.append((ahead, stepped, run.cursor, run.advisories))
        if stepped is None:
            break
        x, y = stepped[4] + 0.01, stepped[5] - 0.02  # a unit that drifts a little
    return out


@pytest.mark.parametrize("to_goal", [False, True])
def test_steering_along_legs_is_steering_along_the_points(to_goal: bool) -> None:
    rng = np.random.default_rng(7)
    corners = _corners(rng, 6)
    goal = (float(corners[-1, 0]), float(corners[-1, 1]))
    zones = ZoneSet([Zone.circle("z", (corners[2, 0] + 9.0, corners[2, 1]), 6.0)])
    for z in (None, zones):
        a = _walk(EscapeRun.along("global", corners, 0.7, to_goal), goal, *corners[0], z)
        b = _walk(EscapeRun("global", resample(corners, 0.7), 0.7, to_goal), goal, *corners[0], z)
        assert len(a) > 50 and a == b


def test_then_joins_legs_as_it_joins_points() -> None:
    rng = np.random.default_rng(3)
    first = _corners(rng, 2)
    second = np.concatenate([first[-1:], _corners(rng, 4)])
    joined = EscapeRun.along("leave", first, 0.5).then(EscapeRun.along("global", second, 0.5, to_goal=True))
    expect = np.concatenate([resample(first, 0.5), resample(second, 0.5)[1:]])
    assert len(joined.segs) and joined.to_goal and np.array_equal(joined.points(), expect)
    mixed = EscapeRun.along("leave", first, 0.5).then(EscapeRun("delta", resample(second, 0.5), 0.5))
    assert not len(mixed.segs) and np.array_equal(mixed.points(), expect)


def test_legs_of_one_corner_are_one_point() -> None:
    run = EscapeRun("x", np.empty((0, 2)), 1.0, segs=legs(np.array([(3.0, 4.0)]), 1.0))
    assert run.end() == (3.0, 4.0)
