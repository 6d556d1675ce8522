"""``pfp bench memory``: the PSS of the planner's process tree, idle and loaded, against issue 23's targets."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from pfp_service.bench.memory import TARGETS, targets


@pytest.mark.unit
def test_targets_judge_the_idle_tree_and_the_loaded_peak():
    doc = {
        "units": 10_000,
        "rate_hz": 1.0,
        "idle": {"pss_mb": TARGETS["idle_pss_mb"] + 1.0},
        "loaded": {"peak": {"pss_mb": TARGETS["loaded_pss_mb"] - 1.0}},
    }
    rows = targets(doc)
    assert [r["met"] for r in rows] == [False, True]
    assert "10000 units at 1 Hz" in rows[1]["target"]
    assert [r["met"] for r in targets({"units": 5, "rate_hz": 2.0, "idle": {}, "loaded": {}})] == [None, None]


@pytest.mark.proc
def test_the_bench_measures_the_planner_and_its_forked_workers():
    out = subprocess.run(
        [sys.executable, "-m", "pfp_service", "bench", "memory", "--units", "20", "--threats", "5"]
        + ["--idle-s", "3", "--load-s", "2", "--json"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    doc = json.loads(out.stdout)
    idle, peak = doc["idle"], doc["loaded"]["peak"]
    assert idle["processes"] >= 3  # the planner, its fork server, one preview worker
    assert 20.0 < idle["pss_mb"] == pytest.approx(sum(idle["pss_mb_by_process"]), abs=0.5)
    assert peak["processes"] >= idle["processes"] and peak["pss_mb"] > 0
    assert doc["exit"]["exit_code"] == 0 and doc["loaded"]["answered_per_s"] > 0
