"""``pfp plan`` run as a user runs it: a subprocess."""

from __future__ import annotations

import json

import pytest

from tests.conftest import EXAMPLES, run_pfp

pytestmark = pytest.mark.proc

KEYS = {
    "status",
    "steps",
    "length",
    "exposure",
    "peak_threat",
    "min_clearance",
    "final_distance",
    "path",
    "compute_ms",
}


def test_summary():
    r = run_pfp("plan", str(EXAMPLES / "paper-simple.yaml"))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("paper-table-1: reached")
    assert "exposure" in r.stdout and "min clearance" in r.stdout


def test_json_repeat_and_plot(tmp_path):
    png = tmp_path / "out.png"
    r = run_pfp(
        "plan", str(EXAMPLES / "paper-contingency.yaml"), "--json", "--repeat", "3", "--plot", str(png)
    )
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc.keys() >= KEYS
    assert doc["status"] == "reached"
    assert len(doc["path"]) == doc["steps"] + 1
    assert doc["compute_ms"] > 0
    assert doc["events"] and "e3" in doc["events"][0]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_overrides_reach_the_core():
    r = run_pfp("plan", str(EXAMPLES / "paper-simple.yaml"), "--json", "--delta", "0.01", "--escape", "none")
    doc = json.loads(r.stdout)
    assert doc["params"]["delta"] == 0.01
    assert doc["status"] == "trapped"


def _one_line_exit_2(r):
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    return r.stderr.strip()


def test_bad_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "start: [0, 0]\ngoal: [10, 10]\nthreats:\n"
        "  - {position: [1, 1], sigma_range: 1, sigma_lateral: 1}\n"
        "  - {position: [2, 2], sigma_range: 1, sigma_lateral: 1}\n"
        "  - {position: [3, 3], sigma_range: -1, sigma_lateral: 1}\n"
    )
    line = _one_line_exit_2(run_pfp("plan", str(bad)))
    assert line == "pfp plan: bad.yaml line 6, threats[2].sigma_range: must be >= 0.001"
    assert (
        _one_line_exit_2(run_pfp("plan", str(_write(tmp_path, "start: [0, 0]\n"))))
        == "pfp plan: s.yaml line 1, goal: is required"
    )
    line = _one_line_exit_2(
        run_pfp("plan", str(_write(tmp_path, "start: [0, 0]\ngoal: [1, 1]\nplanner: {intensity: loud}\n")))
    )
    assert "planner.intensity: unknown value 'loud'" in line
    _one_line_exit_2(run_pfp("plan", str(tmp_path / "missing.yaml")))


def _write(tmp_path, text):
    p = tmp_path / "s.yaml"
    p.write_text(text)
    return p


def test_bad_flags_are_one_line(tmp_path):
    for args in (
        ["--repeat", "0"],
        ["--delta", "nan"],
        ["--intensity", "loud"],
        ["--nope"],
        ["--plot", str(tmp_path / "missing" / "x.png")],
        ["--plot", str(tmp_path / "x.jpeg")],
    ):
        line = _one_line_exit_2(run_pfp("plan", str(EXAMPLES / "paper-simple.yaml"), *args))
        assert line.startswith("pfp")


def test_degenerate_threat_is_one_line(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text(
        "start: [0, 0]\ngoal: [100, 0]\nthreats:\n  - {position: [50, 0], sigma_range: 1.0e-170, sigma_lateral: 5}\n"
    )
    out = run_pfp("plan", str(f), timeout=60)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    assert "sigma_range" in out.stderr


def test_optimal_plan_reports_no_descent_parameters_rather_than_placeholders():
    r = run_pfp("plan", str(EXAMPLES / "paper-simple.yaml"), "--planner", "optimal", "--json")
    assert r.returncode in (0, 1), r.stderr
    params = json.loads(r.stdout)["params"]
    assert params["delta"] is None and params["max_iter"] is None and params["tolerance"] is None
    assert params["step"] > 0  # the grid cell
