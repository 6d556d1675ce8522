"""A wave's share costs less in Python and says the same: ``geo.round_many`` is ``round``, bit for bit.

The look-ahead's lat/lon were rounded one ``round`` call per coordinate, most
of a share's ``with_geodetic_many``; ``round_many`` rounds them in numpy and
hands only the products near a half to ``round``.  A seeded wave's every
direction and event, field by field, is what the per-coordinate rounding gave.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pfp_service import geo
from pfp_service.core import PlannerParams
from pfp_service.wire import Goal, ThreatUpdate, UnitState
from pfp_service.wire import geodetic as wire_geodetic
from pfp_service.world.world import GoalSet, Outputs, StateReported, ThreatPut, Tick, World, WorldSettings

pytestmark = pytest.mark.unit


def _bits(x: float) -> str:
    return x.hex() if x == x else "nan"


def _same(got: list[float], values: list[float], places: int) -> None:
    want = [round(v, places) for v in values]
    assert [_bits(g) for g in got] == [_bits(w) for w in want], values


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=50), st.integers(0, 9))
def test_round_many_is_round_for_any_float(values, places):
    _same(geo.round_many(np.array(values, dtype=float), places), values, places)


def test_round_many_is_round_at_and_beside_every_half():
    """Halves of the 7th place (and the floats either side) of latitudes and longitudes, signs both ways."""
    rng = np.random.default_rng(7)
    k = rng.integers(-1_800_000_000, 1_800_000_000, 20_000)
    halves = (k + 0.5) / 1e7
    values = np.concatenate(
        [halves, np.nextafter(halves, np.inf), np.nextafter(halves, -np.inf), rng.uniform(-180, 180, 20_000)]
    )
    values = np.concatenate([values, [0.0, -0.0, -4e-8, 5e-8, -5e-8, 1e300, -1e-300, 2.5e-7]])
    got = geo.round_many(values.reshape(-1, 2), 7)  # nested, as lat/lon rows
    _same([x for row in got for x in row], values.tolist(), 7)


def _reference(values: np.ndarray, places: int) -> list:
    """The rounding the directions had before: one ``round`` a coordinate."""
    return [[round(float(x), places) for x in row] for row in np.asarray(values)]


def _wave(n: int, seed: int) -> list[Outputs]:
    """A seeded fleet of ``n`` units round a threat put at its centre, with an origin (lat/lon on), and its wave."""
    rng = np.random.default_rng(seed)
    r, a, b = rng.uniform(30.0, 400.0, n), rng.uniform(0, 2 * math.pi, n), rng.uniform(0, 2 * math.pi, n)
    starts = np.column_stack([r * np.sin(a), r * np.cos(a)])
    goals = starts + 25.0 * np.column_stack([np.sin(b), np.cos(b)])
    origin = geo.Origin(lat=33.2, lon=-98.15, alt=300.0)
    w = World(WorldSettings(planner=PlannerParams(), deliberation="deferred", lookahead=5, origin=origin))
    ids = [f"u{i:04d}" for i in range(n)]
    w.apply(
        [StateReported(u, UnitState(position=tuple(p), seq=1)) for u, p in zip(ids, starts.tolist())], 0.0
    )
    outs = [w.apply([GoalSet(u, Goal(position=tuple(p))) for u, p in zip(ids, goals.tolist())], 0.0)]
    threat = ThreatUpdate(position=(0.0, 0.0), sigma_range=150.0, sigma_lateral=150.0)
    outs.append(w.apply([ThreatPut("c", threat)], 1.0))
    now = 1.0
    while w.wave_pending():
        assert len(outs) < 200, "the wave never ends"
        now += 0.002
        outs.append(w.apply([Tick(now, 0)], now))
    return outs


def test_a_seeded_wave_gives_every_field_of_every_direction_it_gave_before(monkeypatch):
    new = _wave(300, seed=32)
    monkeypatch.setattr(wire_geodetic, "round_many", _reference)
    old = _wave(300, seed=32)
    assert len(new) == len(old) > 5  # several shares, then the points
    told = 0
    for a, b in zip(new, old, strict=True):
        assert len(a.directions) == len(b.directions) and len(a.events) == len(b.events)
        for d, e in zip(a.directions, b.directions):
            for field in d.__struct_fields__:
                assert msgspec.json.encode(getattr(d, field)) == msgspec.json.encode(getattr(e, field)), field
            told += bool(d.lookahead_geo)
        assert msgspec.json.encode(a.events) == msgspec.json.encode(b.events)
    assert told >= 300  # every unit's points went out with lat/lon
