"""Plausibility warnings (``pfp_service.plausible``): a scale that looks like a unit mistake is said, never refused."""

from __future__ import annotations

import pytest

from pfp_service import plausible
from pfp_service.scenario import load_scenario
from tests.conftest import EXAMPLES, run_pfp


@pytest.mark.unit
def test_kilometres_as_metres_degrees_as_metres_and_centimetre_threats_are_said():
    km = plausible.warnings((0.0, 0.0), (3000.0, 0.0), [("mg", 350_000.0, 200.0)], has_origin=False)
    assert len(km) == 1 and "threat mg" in km[0] and "kilometres written as metres" in km[0]
    deg = plausible.warnings((15.62, 58.41), (15.64, 58.43), [], has_origin=False)
    assert len(deg) == 1 and "look like degrees" in deg[0]
    assert plausible.warnings((15.62, 58.41), (15.64, 58.43), [], has_origin=True) == []
    tiny = plausible.warnings((0.0, 0.0), (5000.0, 0.0), [("t", 0.001, 0.001)], has_origin=False)
    assert len(tiny) == 1 and "metres written as kilometres" in tiny[0]


@pytest.mark.unit
def test_no_example_scenario_draws_a_warning():
    for path in EXAMPLES.glob("*.yaml"):
        if "team" in path.name or "inject" in path.name:
            continue
        try:
            sc = load_scenario(path)
        except Exception:
            continue  # not a scenario file (a script, a team)
        spreads = [
            (t.id or "t", t.sigma_range, t.sigma_lateral) for t in sc.threats if t.sigma_range is not None
        ]
        assert plausible.warnings(sc.start, sc.goal, spreads, sc.origin is not None) == [], path  # type: ignore[arg-type]


@pytest.mark.proc
def test_pfp_plan_warns_on_stderr_and_plans_all_the_same(tmp_path):
    f = tmp_path / "km.yaml"
    f.write_text(
        "start: [0, 0]\ngoal: [3000, 0]\nthreats:\n  - {id: mg, position: [1500, 900], sigma_range: 350000, sigma_lateral: 200}\n"
    )
    r = run_pfp("plan", str(f), "--json", timeout=120)
    assert r.returncode in (0, 1), r.stderr  # planned: reached or not, never refused for it
    assert r.stderr.startswith(f"pfp plan: warning: {f}: threat mg: a spread of 350,000 m"), r.stderr
    assert r.stdout.lstrip().startswith("{")
