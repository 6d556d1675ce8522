"""Regression tests for the core/CLI review findings: each failed before its fix."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from pfp_service.core.threat import Threat
from pfp_service.errors import InputError
from pfp_service.scenario import decode_scenario
from pfp_service.wire import messages as m

PFP = [sys.executable, "-m", "pfp_service"]


# -- 1. degenerate threats ------------------------------------------------------
def _scenario_yaml(threat: str) -> bytes:
    return f"start: [0, 0]\ngoal: [100, 0]\nthreats:\n  - {threat}\n".encode()


@pytest.mark.parametrize(
    ("threat", "path", "reason"),
    [
        (
            "{position: [50, 0], sigma_range: 1.0e-170, sigma_lateral: 5}",
            "threats[0].sigma_range",
            ">= 0.001",
        ),
        ("{position: [50, 0], sigma_range: 5, sigma_lateral: 0.0}", "threats[0].sigma_lateral", ">= 0.001"),
        ("{position: [50, 0], sigma_range: 1.0e+8, sigma_lateral: 1}", "threats[0].sigma_lateral", "factor"),
        (
            "{position: [50, 0], omega: [[1.0e-170, 0], [0, 1.0e-170]]}",
            "threats[0].omega",
            "positive definite",
        ),
        ("{position: [50, 0], omega: [[1.0e+9, 0], [0, 1.0e-310]]}", "threats[0].omega", "positive definite"),
    ],
)
def test_degenerate_threats_are_rejected_with_their_field(threat, path, reason):
    with pytest.raises(InputError) as exc:
        decode_scenario(_scenario_yaml(threat), "yaml")
    assert exc.value.path == path
    assert reason in exc.value.reason


def test_smallest_sigma_is_usable():
    s = decode_scenario(
        _scenario_yaml("{position: [50, 0], sigma_range: 0.001, sigma_lateral: 1000}"), "yaml"
    )
    t = s.schedule()[0].threat
    assert all(math.isfinite(v) for v in t.precision())


@pytest.mark.parametrize(
    "kwargs",
    [
        {"omega": ((1e-170, 0.0), (0.0, 1e-170))},
        {"omega": ((1.0, 2.0), (2.0, 1.0))},
        {"omega": ((1.0, 0.5), (0.4, 1.0))},
        {"omega": ((math.inf, 0.0), (0.0, 1.0))},
        {"omega": ((1.0, 0.0), (0.0, 1.0)), "alpha": (math.nan, 0.0)},
        {"omega": ((1.0, 0.0), (0.0, 1.0)), "weight": math.inf},
        {"omega": ((1.0, 0.0), (0.0, 1.0)), "weight": -1.0},
    ],
)
def test_threat_refuses_what_it_cannot_evaluate(kwargs):
    args = {"xi": (0.0, 0.0), "alpha": (0.0, 0.0), **kwargs}
    with pytest.raises(ValueError, match="threat"):
        Threat(**args)


def test_threat_from_tiny_sigma_raises_value_error_not_zero_division():
    with pytest.raises(ValueError, match="positive definite"):
        Threat.from_facing((0, 0), 0.0, 1e-170, 1e-170, 0.0)


@pytest.mark.parametrize(
    ("body", "path"),
    [
        (b'{"position": [0, 0], "sigma_range": 1e-170, "sigma_lateral": 5}', "$.sigma_range"),
        (b'{"position": [0, 0], "sigma_range": 1e8, "sigma_lateral": 1}', "$.sigma_lateral"),
    ],
)
def test_wire_threat_rejects_degenerate_sigma(body, path):
    with pytest.raises(InputError) as exc:
        m.decode_threat(body)
    assert exc.value.path == path


def test_wire_what_if_rejects_degenerate_sigma():
    body = b'{"threats": [{"id": "x", "position": [0, 0], "sigma_range": 1e-170, "sigma_lateral": 5}]}'
    with pytest.raises(InputError) as exc:
        m.decode_preview_request(body)
    assert exc.value.path == "$.threats[0].sigma_range"


def test_plan_cli_on_degenerate_threat_is_one_line(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_bytes(_scenario_yaml("{position: [50, 0], sigma_range: 1.0e-170, sigma_lateral: 5}"))
    out = subprocess.run([*PFP, "plan", str(f)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    assert "sigma_range" in out.stderr


# -- 2. look-ahead budget -------------------------------------------------------
def _far_goal_setup():
    from pfp_service.core import PlannerParams, ThreatField, resolve

    threat = Threat.from_facing((5e4, 3.0), 0.0, 10.0, 10.0, 0.0)
    params = resolve(PlannerParams(step=1e-4), (0.0, 0.0), (1e5, 0.0), [threat])
    return ThreatField([threat]), params


def test_derived_max_iter_is_capped_explicit_is_kept():
    from pfp_service.core import PlannerParams, resolve
    from pfp_service.core.params import MAX_ITER_DERIVED

    assert resolve(PlannerParams(step=1e-4), (0, 0), (1e5, 0)).max_iter == MAX_ITER_DERIVED
    assert resolve(PlannerParams(step=1e-4, max_iter=5_000_000), (0, 0), (1e5, 0)).max_iter == 5_000_000
    # the derived step keeps the old rule untouched
    assert resolve(PlannerParams(), (0, 0), (1e5, 0)).max_iter == 1200


def test_look_ahead_is_bounded_and_a_cut_short_simulation_foresees_nothing():
    import time

    from pfp_service.core import foresight
    from pfp_service.core.stepper import Stepper, StepStatus

    field, params = _far_goal_setup()
    sim = foresight.simulate(field, (0.0, 0.0), (1e5, 0.0), params.delta / 1e10, params)
    assert sim.outcome is foresight.Outcome.RUNS_ON
    assert sim.steps == foresight.FORESIGHT_MAX_STEPS
    stepper = Stepper((0.0, 0.0), (1e5, 0.0), params)
    t0 = time.perf_counter()
    advice = stepper.advise(field, 0.0, 0.0)
    assert time.perf_counter() - t0 < 2.0
    assert advice.status is StepStatus.EN_ROUTE and stepper.traps == 0


# -- 3. a trapped verdict follows the unit --------------------------------------
def _trapped_stepper():
    from pfp_service.core import PlannerParams, Stepper, StepStatus, ThreatField, resolve

    block = [Threat.from_facing((5.0, 5.0), 225.0, 1.0, 1.0, 0.0)]
    params = resolve(PlannerParams(delta=0.05, escape="none"), (0.0, 0.0), (10.0, 10.0), block)
    s, field = Stepper((0.0, 0.0), (10.0, 10.0), params), ThreatField(block)
    x, y = 0.0, 0.0
    for _ in range(2000):
        a = s.advise(field, x, y)
        if a.status.terminal:
            break
        x, y = x + params.step * a.dx, y + params.step * a.dy
    assert a.status is StepStatus.TRAPPED
    return s, field, x, y


def test_trapped_verdict_reports_the_position_it_is_asked_about():
    from pfp_service.core.stepper import StepStatus

    s, field, x, y = _trapped_stepper()
    nudge = 0.5 * s.params.step * s.params.trap_window  # still near the trap
    a = s.advise(field, x + nudge, y)
    assert a.status is StepStatus.TRAPPED
    assert math.isclose(a.distance, math.hypot(10.0 - x - nudge, 10.0 - y))
    assert math.isclose(a.level, field.level_grad_at(x + nudge, y)[0])


def test_trapped_unit_walked_away_is_guided_again():
    from pfp_service.core.stepper import StepStatus, advise_many

    s, field, _x, _y = _trapped_stepper()
    a = s.advise(field, 9.0, 4.0)  # carried round the block
    assert a.status is StepStatus.EN_ROUTE
    assert math.isclose(a.distance, math.hypot(1.0, 6.0))
    s2, field, x, y = _trapped_stepper()
    (b,) = advise_many([s2], field, np.array([[9.0, 4.0]]))
    assert b == a
    (c,) = advise_many([_trapped_stepper()[0]], field, np.array([[x, y]]))
    assert c.status is StepStatus.TRAPPED and math.isclose(c.level, field.level_grad_at(x, y)[0])


# -- 5. CLI edges: one line, exit 2 ---------------------------------------------
@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["schemas", "--dir", "/proc/no-such-dir/x"], "cannot write"),
        (
            ["plan", "examples/x.yaml", "--planner", "optimal", "--cells", "50000"],
            "--cells: must be 10 to 5000",
        ),
        (["bench", "quality", "--cells", "0"], "--cells: must be 10 to 5000"),
        (["bench", "quality", "--cells", "-5"], "--cells: must be 10 to 5000"),
    ],
)
def test_cli_edges_are_one_line_exit_2(args, fragment):
    out = subprocess.run([*PFP, *args], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert fragment in out.stderr


def test_thin_threats_are_resolved_by_their_narrow_axis():
    """A 100 m x 1 m threat: its core is about 2.4 m wide, so no segment may step over it."""
    import numpy as np

    from pfp_service.core import PlannerParams, Threat, ThreatField, resolve
    from pfp_service.core.cores import Cores

    thin = Threat.from_facing((50.0, 0.0), 0.0, 100.0, 1.0, 0.0, 1.0, "thin")
    assert abs(thin.min_sigma() - 1.0) < 1e-9 and thin.spread() == 10.0
    cores = Cores(ThreatField([thin]))
    assert cores.inside(np.array([[50.0, 0.0]]))[0]
    assert cores.first_hit(np.array([[48.8, 0.0], [51.3, 0.0]])) == "thin"
    p = resolve(PlannerParams(), (0.0, -300.0), (0.0, 300.0), [thin])
    assert p.step <= 0.25 + 1e-12  # a quarter of the narrow sigma, not of the 10 m spread
