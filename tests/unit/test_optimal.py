"""The optimal reference planner: it must beat or match PFP on J = length + lambda * exposure."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from pfp_service.core import PlannerParams, Scheduled, Threat, ThreatField, plan
from pfp_service.core.optimal import OptimalSolver, plan_optimal

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _simple():
    return [Threat.from_facing(p, 225, 1.0, 0.7, 2.0, 1.0, f"e{i}") for i, p in enumerate([(4, 6), (7, 3)])]


@pytest.mark.unit
@pytest.mark.parametrize("lam", [1.0, 10.0, 100.0])
def test_optimal_beats_or_matches_pfp_on_j(lam):
    threats = _simple()
    pfp = plan((0, 0), (10, 10), [Scheduled(t) for t in threats], PlannerParams(escape="none"))
    assert pfp.status.value == "reached"
    opt = plan_optimal((0, 0), (10, 10), [Scheduled(t) for t in threats], lam, cells=150)
    assert opt.status.value == "reached" and opt.planner == "optimal" and opt.lam == lam
    assert opt.path[0] == (0.0, 0.0) and opt.path[-1] == (10.0, 10.0)
    assert opt.length + lam * opt.exposure <= (pfp.length + lam * pfp.exposure) * 1.001


@pytest.mark.unit
def test_lambda_trades_length_for_exposure():
    field = ThreatField(_simple())
    s = OptimalSolver(field, (0, 0), (10, 10), None, 120)
    short, safe = s.solve(0.0), s.solve(1000.0)
    assert short.length <= safe.length and safe.exposure <= short.exposure
    assert short.length == pytest.approx(math.hypot(10, 10), rel=1e-3)  # shortcuts undo the grid's headings


@pytest.mark.unit
def test_core_free_grid_says_when_no_way_avoids_the_cores():
    ring = [
        Threat.from_facing((14 * math.sin(a), 14 * math.cos(a)), 0, 4, 4, 0.0)
        for a in [k * math.pi / 8 for k in range(16)]
    ]
    s = OptimalSolver(ThreatField(ring), (0, 0), (60, 60), None, 100, avoid_cores=True)
    assert len(s.solve(0.0).path) == 0


@pytest.mark.proc
def test_cli_optimal_prints_the_same_json_object():
    args = [sys.executable, "-m", "pfp_service", "plan", str(EXAMPLES / "paper-simple.yaml"), "--json"]
    pfp = json.loads(subprocess.run(args, capture_output=True, text=True, check=True).stdout)
    r = subprocess.run(
        [*args, "--planner", "optimal", "--lambda", "10", "--cells", "120"], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    opt = json.loads(r.stdout)
    assert set(pfp) == set(opt)
    assert opt["planner"] == "optimal" and opt["lambda"] == 10 and opt["status"] == "reached"
    assert opt["length"] + 10 * opt["exposure"] <= pfp["length"] + 10 * pfp["exposure"]


@pytest.mark.proc
def test_cli_avoid_cores_is_a_safe_reference(tmp_path):
    ring = "\n".join(
        f"  - {{position: [{20 + 14 * math.sin(a):.6f}, {20 + 14 * math.cos(a):.6f}], facing_deg: 0, "
        "sigma_range: 4, sigma_lateral: 4, skew: 0}"
        for a in [k * math.pi / 8 for k in range(16)]
    )
    scn = tmp_path / "ring.yaml"
    scn.write_text(f"name: ring\nstart: [20, 20]\ngoal: [100, 100]\nthreats:\n{ring}\n")
    base = [
        sys.executable,
        "-m",
        "pfp_service",
        "plan",
        str(scn),
        "--json",
        "--planner",
        "optimal",
        "--cells",
        "80",
    ]
    free = subprocess.run(base, capture_output=True, text=True)
    assert json.loads(free.stdout)["status"] == "reached"  # ignoring cores it drives through the ring
    safe = subprocess.run([*base, "--avoid-cores"], capture_output=True, text=True)
    out = json.loads(safe.stdout)
    assert safe.returncode == 1 and out["status"] == "trapped" and "threat cores" in out["reason"]
