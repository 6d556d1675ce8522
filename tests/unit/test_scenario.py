"""Scenario files: every bad value gets one line naming its field path."""

from __future__ import annotations

import json
import math

import pytest

from pfp_service.errors import InputError
from pfp_service.scenario import decode_scenario, load_scenario

pytestmark = pytest.mark.unit

GOOD = {
    "name": "t",
    "start": [0, 0],
    "goal": [10, 10],
    "planner": {"delta": 0.08, "intensity": "density"},
    "threats": [
        {"id": "a", "position": [4, 6], "facing_deg": 225, "sigma_range": 1, "sigma_lateral": 0.7, "skew": 2},
        {"position": [7, 3], "sigma_range": 1, "sigma_lateral": 1},
        {"id": "c", "position": [5, 5], "sigma_range": 1, "sigma_lateral": 1, "appear_step": 10},
    ],
}


def _with(path: str, value) -> dict:
    doc = json.loads(json.dumps(GOOD))
    keys = path.split(".")
    node = doc
    for k in keys[:-1]:
        node = node[int(k)] if k.isdigit() else node[k]
    last = keys[-1]
    if value is _DELETE:
        del node[int(last) if last.isdigit() else last]
    else:
        node[int(last) if last.isdigit() else last] = value
    return doc


_DELETE = object()


def _error(doc, fmt="json") -> str:
    data = json.dumps(doc).encode() if fmt == "json" else doc
    with pytest.raises(InputError) as info:
        decode_scenario(data, fmt)
    return str(info.value)


def test_good_scenario_decodes():
    s = decode_scenario(json.dumps(GOOD).encode(), "json")
    sched = s.schedule()
    assert [x.threat.id for x in sched] == ["a", "t2", "c"]
    assert sched[2].appear_step == 10
    assert s.planner.to_params().intensity == "density"


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        ("threats.2.sigma_range", -1, "threats[2].sigma_range: must be >= 0.001"),
        ("threats.0.sigma_lateral", 0, "threats[0].sigma_lateral: must be >= 0.001"),
        ("threats.0.skew", -0.5, "threats[0].skew: must be >= 0"),
        ("threats.1.weight", -1, "threats[1].weight: must be >= 0"),
        ("threats.0.appear_step", -3, "threats[0].appear_step: must be >= 0"),
        ("threats.0.position", [1], "threats[0].position: expected array of length 2"),
        ("threats.0.facing_deg", "north", "threats[0].facing_deg: expected float, got str"),
        ("threats.0.id", "bad id!", "threats[0].id: expected str matching regex"),
        ("threats.1.sigma_range", _DELETE, "threats[1].sigma_range: is required"),
        (
            "planner.intensity",
            "loud",
            "planner.intensity: unknown value 'loud' (expected one of: peak, density)",
        ),
        ("planner.escape", "teleport", "planner.escape: unknown value 'teleport'"),
        ("planner.delta", 0, "planner.delta: must be >= 1e-09"),
        ("planner.max_iter", 0, "planner.max_iter: must be >= 1"),
        ("planner.bogus", 1, "planner.bogus: unknown field"),
        ("goal", _DELETE, "goal: is required"),
        ("start", [0, 1e300], "start[1]: expected a finite number"),
        ("bounds", [[0, 0], [5, 5]], "goal: lies outside bounds"),
        ("bounds", [[5, 0], [1, 5]], "bounds: must be [[xmin, ymin], [xmax, ymax]]"),
        ("threats.1.id", "a", "threats[1].id: duplicate id 'a'"),
    ],
)
def test_bad_values_name_their_field(path, value, message):
    err = _error(_with(path, value))
    assert err.startswith(message), err
    assert "\n" not in err


def test_yaml_nan_and_inf_are_rejected():
    doc = b"start: [0, .nan]\ngoal: [1, 1]\n"
    assert _error(doc, "yaml").startswith("start[1]: expected a finite number")
    doc = b"start: [0, 0]\ngoal: [1, 1]\nthreats: [{position: [.inf, 0], sigma_range: 1, sigma_lateral: 1}]\n"
    assert _error(doc, "yaml").startswith("threats[0].position[0]: expected a finite number")
    doc = b"start: [0, 0]\ngoal: [1, 1]\nthreats: [{position: [0, 0], sigma_range: .nan, sigma_lateral: 1}]\n"
    assert _error(doc, "yaml").startswith("threats[0].sigma_range: must be >= 0.001")


def test_raw_form():
    raw = {"position": [1, 1], "omega": [[1.0, 0.2], [0.2, 0.5]], "alpha": [1.0, -2.0]}
    s = decode_scenario(json.dumps({**GOOD, "threats": [raw]}).encode(), "json")
    t = s.schedule()[0].threat
    assert t.omega == ((1.0, 0.2), (0.2, 0.5)) and t.alpha == (1.0, -2.0)
    bad = {**raw, "omega": [[1.0, 2.0], [2.0, 0.5]]}
    assert _error({**GOOD, "threats": [bad]}) == "threats[0].omega: must be positive definite"
    asym = {**raw, "omega": [[1.0, 0.1], [0.2, 0.5]]}
    assert _error({**GOOD, "threats": [asym]}) == "threats[0].omega: must be symmetric"
    both = {**raw, "sigma_range": 1.0}
    assert "give either omega or sigma_range" in _error({**GOOD, "threats": [both]})


def test_a_bad_field_names_the_file_and_its_line(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text(
        "start: [0, 0]\ngoal: [10, 0]\nthreats:\n  - {position: [5, 0], sigma_range: -1, sigma_lateral: 1}\n"
    )
    with pytest.raises(InputError) as e:
        load_scenario(p)
    assert str(e.value) == "bad.yaml line 4, threats[0].sigma_range: must be >= 0.001"
    q = tmp_path / "bad.json"
    q.write_text('{"start": [0, 0], "goal": [10, 0], "step": -1}')
    with pytest.raises(InputError, match=r"^bad\.json line 1, step: "):
        load_scenario(q)


def test_malformed_files(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("start: [0, 0\ngoal: [1, 1]\n")
    with pytest.raises(InputError, match=r"^s\.yaml line \d+, column \d+: invalid YAML"):
        load_scenario(p)
    p.write_text("- just\n- a list\n")
    with pytest.raises(InputError, match="must be a mapping"):
        load_scenario(p)
    q = tmp_path / "s.json"
    q.write_text("{nope")
    with pytest.raises(InputError, match="malformed JSON"):
        load_scenario(q)
    with pytest.raises(InputError, match="must end in"):
        load_scenario(tmp_path / "s.txt")
    with pytest.raises(InputError, match="cannot read"):
        load_scenario(tmp_path / "missing.yaml")


def test_yaml_exponent_floats_are_numbers(tmp_path):
    """PyYAML (YAML 1.1) reads 1e3 as a string; our loader reads YAML 1.2 floats."""
    doc = b"start: [0, 0]\ngoal: [1e3, 2.5e+2]\nthreats: [{position: [5e2, 1E2], sigma_range: 1e2, sigma_lateral: 5e1}]\n"
    s = decode_scenario(doc, "yaml")
    assert s.goal == (1000.0, 250.0)
    assert s.threats[0].sigma_range == 100.0 and s.threats[0].position == (500.0, 100.0)
    quoted = b"name: '1e3'\nstart: [0, 0]\ngoal: [1, 1]\n"
    assert decode_scenario(quoted, "yaml").name == "1e3"


def test_team_files_read_exponent_floats_too(tmp_path):
    from pfp_service.team import load_team

    p = tmp_path / "team.yaml"
    p.write_text(
        "name: t\nunits:\n  - {id: a, kind: manned, start: [0, 0], goal: [1e3, 0], speed_mps: 1.5e0}\n"
    )
    team = load_team(p)
    assert team.units[0].goal == (1000.0, 0.0)


def _one_threat(threat: str) -> bytes:
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
        decode_scenario(_one_threat(threat), "yaml")
    assert exc.value.path == path
    assert reason in exc.value.reason


def test_smallest_sigma_is_usable():
    s = decode_scenario(_one_threat("{position: [50, 0], sigma_range: 0.001, sigma_lateral: 1000}"), "yaml")
    t = s.schedule()[0].threat
    assert all(math.isfinite(v) for v in t.precision())
