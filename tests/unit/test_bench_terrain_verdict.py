"""``pfp bench terrain``'s bystanders' verdict: a ratio within 20 % counts only where the noise floor can resolve it."""

from __future__ import annotations

from typing import Any

import pytest

from benchmarks._terrain_live import BYSTANDER_TARGET, met, unresolved

pytestmark = pytest.mark.unit


def _live(ratio: float | None, floor: float | None, wave_ms: float | None = 40.0) -> dict[str, Any]:
    by: dict[str, Any] = {"p99_ratio": ratio}
    if floor is not None:
        by["A_halves_p99_ratio"] = floor
    return {"wave": {"all_redirected_ms": wave_ms}, "bystanders": by}


@pytest.mark.parametrize(
    ("ratio", "floor", "ok"),
    [
        (1.10, 1.05, True),  # within 20 %, on a floor that resolves 20 %
        (1.10, 0.90, True),  # a floor below 1 is the same spread the other way round: 1.11x
        (1.20, 1.20, True),  # both exactly at the line
        (1.25, 1.05, False),  # outside 20 %: missed whatever the floor
        (1.01, 3.83, False),  # within 20 %, but plain against plain differs by 3.83x: noise
        (1.01, 0.80, False),  # 1 / 0.80 = 1.25x apart, the other way round
        (1.01, None, False),  # one pair: no floor to judge it against
        (None, 1.05, False),  # no ratio at all
    ],
)
def test_the_bystanders_row_is_met_only_within_20_percent_on_a_floor_that_resolves_it(ratio, floor, ok):
    wave_ok, by_ok = met(_live(ratio, floor))
    assert wave_ok and by_ok is ok


def test_the_reason_names_the_floor_or_its_absence():
    assert unresolved({"A_halves_p99_ratio": 1.05}) is None
    assert unresolved({"A_halves_p99_ratio": 3.83}) == "plain against plain already differs by 3.83x"
    assert unresolved({"A_halves_p99_ratio": 0.5}) == "plain against plain already differs by 2.00x"
    none = "no noise floor to judge it against (one window pair, or a half without answers)"
    assert unresolved({}) == none and unresolved({"A_halves_p99_ratio": None}) == none
    assert unresolved({"A_halves_p99_ratio": 0.0}) == none
    assert unresolved({"A_halves_p99_ratio": BYSTANDER_TARGET}) is None


def test_the_wave_is_judged_apart_from_the_bystanders():
    assert met(_live(1.05, 1.02, wave_ms=120.0)) == (False, True)
    assert met(_live(1.05, 1.02, wave_ms=None)) == (False, True)
    assert met({"not_run": "no gdal"}) == (False, False)
