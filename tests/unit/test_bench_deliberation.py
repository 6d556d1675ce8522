"""``bench._deliberation``: the storm's look-aheads and the wave, measured in process on a small fleet."""

from __future__ import annotations

import pytest

from benchmarks._deliberation import storm_and_wave

pytestmark = pytest.mark.unit


def test_a_small_storm_runs_every_look_ahead_and_the_wave_redirects_the_fleet():
    d = storm_and_wave(units=24, repeat=1)
    assert d["lookaheads"] == 24  # one look-ahead per goal
    assert sum(d["routes"].values()) == 24
    assert 0.0 <= d["foresaw_trap_fraction"] <= 1.0
    c = d["lookahead_cpu_ms"]
    assert 0.0 < c["p50"] <= c["p90"] <= c["max"]
    assert d["one_worker_s"] > 0.0
    wave = d["wave"]
    assert wave["directions"] > 0  # the threat ahead of the fleet reaches units
    assert wave["apply_ms_median"] > 0.0 and len(wave["apply_ms_all"]) == 1
