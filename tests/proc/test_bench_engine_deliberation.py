"""``pfp bench engine --deliberation-only`` runs the storm and wave rows alone, as a user runs it."""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_pfp

pytestmark = pytest.mark.proc


def test_deliberation_only_reports_the_storm_and_the_wave_and_their_checks() -> None:
    got = run_pfp("bench", "engine", "--deliberation-only", "--quick", "--json", timeout=300)
    assert got.returncode == 0, got.stderr
    doc = json.loads(got.stdout)
    assert set(doc) == {"machine", "deliberation", "checks"}  # no table, platoon or scale rows
    d = doc["deliberation"]
    assert d["units"] == 100 and d["lookaheads"] > 0
    assert d["lookahead_cpu_ms"]["mean"] > 0 and d["one_worker_s"] > 0
    assert d["wave"]["directions"] > 0
    assert len(doc["checks"]) == 2 and all(isinstance(v, bool) for v in doc["checks"].values())


def test_deliberation_only_prints_the_two_rows_and_check_gates_them() -> None:
    got = run_pfp("bench", "engine", "--deliberation-only", "--quick", timeout=300)
    assert got.returncode == 0, got.stderr  # without --check a run reports and exits 0
    assert "goal storm, 100 distinct goals" in got.stdout and "contingency wave" in got.stdout
    assert "MAXITER" not in got.stdout  # the paper's table is not run
    assert got.stdout.count("[ok]") + got.stdout.count("[MISSED]") == 2
