"""``steering.reached`` over a fleet: each unit as its own corridor test says, and every unit when one cannot be read."""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Stepper, resolve
from pfp_service.core.cull import corridors_meet, influence_boxes
from pfp_service.core.threat import ThreatField
from pfp_service.wire import ThreatUpdate
from pfp_service.world import steering, translate
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
    got = steering.reached(guided, touched, "peak", zones)
    boxes = influence_boxes(ThreatField(touched, "peak").packed)
    zb = np.array(zones)
    pad = steering.ZONE_REACH * np.hypot(zb[:, 2] - zb[:, 0], zb[:, 3] - zb[:, 1])[:, None]
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
    assert steering.reached(guided, touched, "peak") == [True] * 20
