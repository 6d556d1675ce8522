"""``pfp bench memory``: the PSS of the planner's process tree, idle and loaded, against issue 23's targets."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from benchmarks.memory import TARGETS, pss_by_mapping, targets


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


@pytest.mark.unit
def test_a_process_pss_is_split_by_kind_of_mapping():
    smaps = "\n".join(
        [
            "55d0c0000000-55d0c8000000 rw-p 00000000 00:00 0                          [heap]",
            "Size:             131072 kB",
            "Pss:               20480 kB",
            "7f0000000000-7f0004000000 rw-p 00000000 00:00 0 ",
            "Pss:               10240 kB",
            "7f0010000000-7f0010100000 r-xp 00000000 08:01 42                         /usr/lib/libc.so.6",
            "Pss:                1024 kB",
            "7ffd00000000-7ffd00021000 rw-p 00000000 00:00 0                          [stack]",
            "Pss:                 512 kB",
            "7f0020000000-7f0020001000 rw-p 00000000 00:00 0",
            "Pss:                1024 kB",
        ]
    )
    assert pss_by_mapping(smaps) == {"heap": 20.0, "anon": 11.0, "file": 1.0, "other": 0.5}


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
    split = doc["quiet"]["planner_by_mapping"]  # the planner's own PSS, by kind of mapping
    assert split["file"] > 1.0 and split["heap"] + split["anon"] > 1.0
    assert sum(split.values()) == pytest.approx(doc["quiet"]["pss_mb_by_process"][0], abs=1.0)
