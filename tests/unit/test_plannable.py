"""What the planner cannot plan is refused, with one bound written once (``constraints``) for wire, files and flags.

A subnormal or absurd step, tolerance or delta is refused with its field
path; a step that would need more than ``max_iter`` steps to cover the
distance is refused where the distance is known (a scenario file, ``pfp
plan``'s flags, a goal when its mission is fixed); a goal closer than the
tolerance has simply arrived.
"""

from __future__ import annotations

import argparse
import json

import pytest

from pfp_service.constraints import Delta, Step, Tolerance, flag_type, reach_problem
from pfp_service.core import PlannerParams, resolve
from pfp_service.core.params import MAX_ITER_DERIVED, reach
from pfp_service.errors import InputError
from pfp_service.node.config import load_config
from pfp_service.scenario import decode_scenario
from pfp_service.wire import decode_goal, decode_preview_request
from tests.conftest import run_pfp

SUB = 5e-324


def _scenario(**planner) -> bytes:
    return json.dumps({"start": [0, 0], "goal": [1e5, 0], "planner": planner}).encode()


@pytest.mark.unit
@pytest.mark.parametrize(
    ("field", "value", "reason"),
    [
        ("step", SUB, "must be >= 0.001"),
        ("step", 1e-300, "must be >= 0.001"),
        ("tolerance", SUB, "must be >= 0.001"),
        ("delta", SUB, "must be >= 1e-09"),
        ("delta", 0.0, "must be >= 1e-09"),
        ("delta", 2e9, "expected a finite number within ±1e+09"),
    ],
)
def test_the_same_bound_refuses_the_same_value_on_the_wire_in_a_file_and_in_a_flag(field, value, reason):
    with pytest.raises(InputError) as wire:
        decode_goal(json.dumps({"position": [10, 10], field: value}).encode())
    assert (wire.value.path, wire.value.reason) == (f"$.{field}", reason)
    with pytest.raises(InputError) as preview:
        decode_preview_request(json.dumps({field: value}).encode())
    assert preview.value.path == f"$.{field}"
    with pytest.raises(InputError) as file:
        decode_scenario(_scenario(**{field: value}), "json")
    assert str(file.value) == f"planner.{field}: {reason}"
    with pytest.raises(InputError) as config:
        load_config(None, {}, {field: value})
    assert field in str(config.value)
    kind = {"step": Step, "tolerance": Tolerance, "delta": Delta}[field]
    with pytest.raises(argparse.ArgumentTypeError, match="must be a finite number >= "):
        flag_type(kind)(repr(value))


@pytest.mark.unit
def test_a_step_too_fine_for_its_distance_is_refused_where_the_distance_is_known():
    want = "a step of 0.001 m needs 1e+08 steps to come within 0.00075 m of a goal 100000 m away"
    with pytest.raises(InputError) as file:
        decode_scenario(_scenario(step=1e-3), "json")
    assert file.value.path == "planner.step" and want in file.value.reason
    assert "more than max_iter (1,000,000)" in file.value.reason
    decode_scenario(_scenario(step=1e-3, max_iter=5), "json")  # a cap asked for: a plan that stops at it
    decode_scenario(_scenario(step=1.0), "json")  # 1e5 steps: within the derived max_iter
    assert reach(PlannerParams(step=1e-3), (0.0, 0.0), (5e-4, 0.0)) is None  # within tolerance: arrived


@pytest.mark.unit
def test_reach_problem_is_a_value_for_any_numbers():
    assert reach_problem(1e5, 1e-3, MAX_ITER_DERIVED, 7.5e-4) is not None
    assert reach_problem(5e-324, 1e-3, 300, 7.5e-4) is None  # closer than the tolerance: arrived
    assert reach_problem(0.0, SUB, 300, 0.0) is None  # on the goal
    for bad in (float("nan"), float("inf"), -1.0, 0.0):
        assert "cannot plan" in (reach_problem(10.0, bad, 300, 0.1) or "")
    assert "cannot plan" in (reach_problem(float("nan"), 0.1, 300, 0.1) or "")


@pytest.mark.unit
@pytest.mark.parametrize("offset", [0.0, SUB, 1e-300, 1e-160, 1e-10])
def test_resolve_is_total_and_a_goal_closer_than_it_resolves_has_arrived(offset):
    r = resolve(PlannerParams(), (0.0, 0.0), (offset, offset))
    assert r.step > 0 and r.tolerance > 0 and 300 <= r.max_iter <= MAX_ITER_DERIVED
    assert (offset * 2**0.5) <= r.tolerance or offset >= 1e-10
    for step in (
        SUB,
        1e-300,
        1e-3,
    ):  # an explicit step too fine for any plan: the cap, never an OverflowError
        assert resolve(PlannerParams(step=step), (0.0, 0.0), (1e9, 1e9)).max_iter == MAX_ITER_DERIVED


@pytest.mark.proc
def test_pfp_plan_and_pfp_serve_refuse_them_in_one_line(tmp_path):
    far = tmp_path / "far.json"
    far.write_bytes(_scenario(step=0.5))
    r = run_pfp("plan", str(far), "--step", "0.001", timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert "--step: a step of 0.001 m needs 1e+08 steps" in line, line
    r = run_pfp("serve", "--step", "5e-324", "--listen", "tcp/127.0.0.1:1", timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert "--step: must be a finite number >= 0.001 (at most 1e+09), got '5e-324'" in line, line
