"""``pfp bench libraries``: the measurement behind keeping our NMEA parser and worker pool."""

from __future__ import annotations

import pytest

from benchmarks.libraries import _HOSTILE, _nmea

pytestmark = pytest.mark.unit


def test_no_hostile_sentence_becomes_a_fix_with_our_parser_and_the_bench_can_tell():
    got = _nmea()
    assert set(got["cases"]) == set(_HOSTILE)
    assert got["fixed_from_hostile"]["ours"] == 0
    # the comparison can fail: pynmea2 places at least the out-of-range latitude somewhere
    assert got["cases"]["latitude 95 degrees"]["pynmea2"].startswith("fix")
    assert got["ours_us"] > 0 and got["pynmea2_us"] > 0
