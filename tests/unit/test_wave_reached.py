"""``reach.reached`` over a fleet: each unit as its own corridor test says, and every unit when one cannot be read."""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Stepper, resolve
from pfp_service.core.cull import RELATIVE_BOUND, corridors_meet, influence_boxes
from pfp_service.core.threat import ThreatField
from pfp_service.wire import ThreatUpdate
from pfp_service.world import reach, translate
from pfp_service.world.world_records import Records

pytestmark = pytest.mark.unit


def _fleet(seed: int, n: int) -> list:
    rng = random.Random(seed)
    recs, out = Records(), []
    for i in range(n):
        rec = recs.book.add(f"u{i}", True, 0.0, reported=True)
        rec.position = (rng.uniform(-500, 500), rng.uniform(-500, 500))
        goal = (rng.uniform(-500, 500), rng.uniform(-500, 500))
        rec.stepper = Stepper(rec.position, goal, resolve(PlannerParams(), rec.position, goal, ()))
        out.append(rec)
    return out


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_each_unit_is_reached_as_its_own_corridor_says(seed):
    guided = _fleet(seed, 200)
    touched = [translate.threat(ThreatUpdate(position=(0.0, 0.0), sigma_range=30.0, sigma_lateral=20.0), "t")]
    zones = [(100.0, 100.0, 140.0, 180.0)]
    got = reach.reached(guided, touched, "peak", zones)
    boxes = influence_boxes(ThreatField(touched, "peak").packed)
    zb = np.array(zones)
    pad = reach.ZONE_REACH * np.hypot(zb[:, 2] - zb[:, 0], zb[:, 3] - zb[:, 1])[:, None]
    boxes = np.concatenate([boxes, zb + np.hstack([-pad, -pad, pad, pad])])
    want = [
        bool(corridors_meet(np.array([r.position]), np.array([r.stepper.goal]), boxes)[0]) for r in guided
    ]
    assert got == want and any(got) and not all(got), f"seed {seed}"
    assert all(type(b) is bool for b in got)


def test_a_unit_that_cannot_be_read_makes_every_unit_reached():
    guided = _fleet(4, 20)
    guided[7].position = (float("nan"),)  # type: ignore[assignment]
    touched = [
        translate.threat(ThreatUpdate(position=(5000.0, 5000.0), sigma_range=1.0, sigma_lateral=1.0), "t")
    ]
    assert reach.reached(guided, touched, "peak") == [True] * 20


def test_over_terrain_a_threat_reaches_only_the_units_it_can_see():
    """A threat behind a ridge: the unit in the valley it cannot see keeps its direction; the one in its view is re-told."""
    from pfp_service.core import Threat
    from pfp_service.terrain.grid import TerrainGrid
    from pfp_service.terrain.threat_sight import TerrainSight

    xs = np.arange(-3000.0, 3000.0 + 10.0, 20.0)
    gx, _ = np.meshgrid(xs, xs)
    ridge = TerrainGrid(-3000.0, -3000.0, 20.0, np.maximum(0.0, 60.0 - 0.2 * np.abs(gx)))  # along x = 0
    sight = TerrainSight(ridge, 1.8)
    behind = Threat.from_facing((-1000.0, 0.0), 90.0, 800.0, 800.0, 0.0, 1.0, "t", observer_height_m=2.0)
    recs = Records()
    fleet = []
    for uid, x in (("valley", 600.0), ("front", -500.0)):  # east of the ridge, hidden; west of it, in view
        rec = recs.book.add(uid, True, 0.0, reported=True)
        rec.position = (x, -300.0)
        rec.stepper = Stepper(
            rec.position, (x, 300.0), resolve(PlannerParams(), rec.position, (x, 300.0), ())
        )
        fleet.append(rec)
    assert reach.reached(fleet, [behind], "peak") == [True, True]  # blind: both corridors meet its box
    assert reach.reached(fleet, [behind], "peak", (), sight) == [False, True]
    # the cause, measured apart: the masked field is nil along the valley's corridor, not in front
    valley = np.column_stack([np.full(7, 600.0), np.linspace(-300.0, 300.0, 7)])
    front = np.column_stack([np.full(7, -500.0), np.linspace(-300.0, 300.0, 7)])
    masked = ThreatField([behind], "peak", sight=sight)
    assert masked.level(valley).max() < 1e-6 * ThreatField([behind], "peak").level(valley).max()
    assert masked.level(front).min() > 0.5 * ThreatField([behind], "peak").level(front).min()


def test_over_terrain_each_wide_unit_is_reached_as_its_own_box_says(monkeypatch):
    """A wave's deliberating units, judged all at once, each as the threat's sight over its own widened box says."""
    monkeypatch.setattr(reach, "WIDE_BLOCK", 7)  # several blocks, the last one short
    from pfp_service.core import Threat
    from pfp_service.terrain.grid import TerrainGrid
    from pfp_service.terrain.threat_sight import TerrainSight

    xs = np.arange(-3000.0, 3000.0 + 10.0, 20.0)
    gx, gy = np.meshgrid(xs, xs)
    hills = 40.0 * np.sin(gx / 310.0) * np.cos(gy / 420.0) + 25.0 * np.sin((gx + gy) / 230.0)  # no symmetry
    sight = TerrainSight(TerrainGrid(-3000.0, -3000.0, 20.0, hills + 100.0), 1.8)
    behind = Threat.from_facing((-1000.0, 0.0), 90.0, 800.0, 800.0, 0.0, 1.0, "t", observer_height_m=2.0)
    guided = _fleet(5, 120)
    for rec in guided:  # spread over the hills, short corridors
        x, y = rec.position[0] * 5.0, rec.position[1] * 5.0
        rec.position, rec.stepper.goal = (x, y), (x + 100.0, y + 60.0)
    got = reach.reached(guided, [behind], "peak", (), sight, [True] * len(guided))
    box = influence_boxes(ThreatField([behind], "peak").packed)[0]
    blind_f, masked_f = ThreatField([behind], "peak"), ThreatField([behind], "peak", sight=sight)
    want = []
    for rec in guided:  # one unit at a time, as the box is read point by point
        s, g = np.array(rec.position), np.array(rec.stepper.goal)
        pad = reach.WIDE_REACH * float(np.hypot(*(g - s)))
        lo, hi = np.maximum(np.minimum(s, g) - pad, box[:2]), np.minimum(np.maximum(s, g) + pad, box[2:])
        if (lo > hi).any():
            want.append(False)
            continue
        k = reach.WIDE_SAMPLES
        px, py = np.meshgrid(np.linspace(lo[0], hi[0], k), np.linspace(lo[1], hi[1], k))
        pts = np.column_stack([px.ravel(), py.ravel()])
        blind, masked = blind_f.level(pts), masked_f.level(pts)
        want.append(bool(((blind > 0.0) & (masked >= RELATIVE_BOUND * blind)).any()))
    assert got == want and any(got) and not all(got)
