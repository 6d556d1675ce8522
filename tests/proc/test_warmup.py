"""The warm-up loads every kernel a big tick uses: after it, nothing compiles in the live loop (issue 32).

Each case runs ``tests/warm_big_tick.py`` in a fresh interpreter (kernels
another test loaded would hide a gap): the warm-up, then a tick of 48
threats masked over a ridge, 150 units (``UNITS``: the script's 600 cost
90 s a run on a loaded 2-core machine and probe no more kernels, only
others), and three units trapped in a box of keep-out zone with one goal.  No numba dispatcher of pfp_service may gain a
signature in that tick; without the wide warm-up several do.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.proc

SCRIPT = Path(__file__).resolve().parents[1] / "warm_big_tick.py"
ROOT = SCRIPT.parent.parent
UNITS = 150


def _tick(*flags: str) -> dict[str, object]:
    r = subprocess.run(
        [sys.executable, str(SCRIPT), f"--units={UNITS}", *flags],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def test_nothing_compiles_in_a_big_tick_after_the_warm_up() -> None:
    got = _tick()
    assert any("route" in str(r) for r in got["reasons"]), got  # type: ignore[union-attr]
    assert got["grown"] == {}, got


def test_the_big_tick_reaches_kernels_only_the_wide_warm_up_loads() -> None:
    grown = _tick("--no-wide")["grown"]
    for kernel in (
        "cull._culled_descent",
        "grid._edges",
        "cores._raster",
        "viewshed._sweep",
        "neighbour_kernels.pair_terms",
        "neighbour_kernels.within",
        "keep_apart_kernels.cut",
    ):
        assert any(k.endswith(kernel) for k in grown), (kernel, grown)  # type: ignore[union-attr]
