"""``pfp inject`` against a real planner and a real ``pfp fleet``, all subprocesses on loopback."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import uuid
from typing import Any

import pytest
from pfp_clients.script import load_script

from pfp_service.errors import InputError
from tests.conftest import EXAMPLES, ROOT, run_pfp
from tests.zenoh_util import client, planner_process

SPEED_UP = "10"


@pytest.fixture
def mission():
    return "i" + uuid.uuid4().hex[:10]


def _pfp(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for_line(proc: subprocess.Popen[str], needle: str, timeout: float = 20.0) -> list[str]:
    seen = []
    deadline = time.monotonic() + timeout
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        seen.append(line)
        if needle in line:
            return seen
    raise AssertionError(f"{needle!r} never printed; got {seen}")


@pytest.mark.proc
def test_figure_8_expectations_hold_and_a_failing_one_exits_1(tmp_path, mission):
    failing = tmp_path / "strict.yaml"
    text = (EXAMPLES / "figure8-inject.yaml").read_text()
    failing.write_text(
        text.replace("arrives_within_s: 60", "arrives_within_s: 2").replace(
            "min_clearance_m: 1.0", "min_clearance_m: 4.0"
        )
    )
    with planner_process("--intensity", "density", mission=mission) as (endpoint, _):
        common = ("--connect", endpoint, "--mission", mission, "--speed-up", SPEED_UP)
        good = _pfp("inject", str(EXAMPLES / "figure8-inject.yaml"), *common)
        strict = _pfp("inject", str(failing), *common)
        try:
            head = _wait_for_line(good, "set goal of u1")
            _wait_for_line(strict, "set goal of u1")
            fleet = run_pfp(
                "fleet", "--team", str(EXAMPLES / "figure8-team.yaml"), *common,
                "--until-arrived", "--duration-s", "100", timeout=60,
            )  # fmt: skip
            out, err = good.communicate(timeout=30)
            s_out, s_err = strict.communicate(timeout=30)
        finally:
            for p in (good, strict):
                if p.poll() is None:
                    p.kill()
    assert fleet.returncode == 0, fleet.stdout + fleet.stderr
    out = "".join(head) + out
    assert good.returncode == 0, out + err
    assert "add threat e3 at (6, 7)  (when u1 at (" in out  # the contingency struck mid-route
    assert "PASS  u1 arrives within 60 s" in out
    assert "PASS  min clearance of u1 to e3 >= 1 m" in out
    assert "2/2 expectations held" in out
    assert strict.returncode == 1, s_out + s_err
    assert "FAIL  u1 arrives within 2 s: arrived at" in s_out
    assert "FAIL  min clearance of u1 to e3 >= 4 m: min clearance" in s_out
    assert "FAILED" in s_out


@pytest.mark.proc
def test_bad_script_is_one_line_exit_2_and_nothing_is_sent(tmp_path, mission):
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "timeline:\n"
        "  - {do: add_threat, threat: e1, position: [1, 1], sigma_range: 1, sigma_lateral: 1}\n"
        "  - {do: set_goal, unit: u1, position: [5, 5]}\n"
        "  - do: add_threat\n"
        "    threat: e2\n"
        "    position: [2, 2]\n"
        "    sigma_range: 0\n"
        "    sigma_lateral: 1\n"
    )
    with planner_process(mission=mission) as (endpoint, _), client(endpoint) as s:
        heard = []
        s.declare_subscriber(f"mumt/{mission}/**", lambda smp: heard.append(str(smp.key_expr)))
        time.sleep(0.3)
        r = run_pfp("inject", str(bad), "--connect", endpoint, "--mission", mission, timeout=30)
        time.sleep(0.5)
    assert r.returncode == 2
    assert r.stderr.strip() == "pfp inject: bad.yaml line 7, timeline[2].sigma_range: must be >= 0.001"
    assert r.stdout == ""
    assert heard == []


@pytest.mark.unit
@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            "timeline:\n  - {do: fly, unit: u1}\n",
            "line 2, timeline[0].do: invalid value 'fly' (expected one of:",
        ),
        ("timeline:\n  - {do: remove_threat, threat: e9}\n", "line 2, timeline[0].threat: 'e9' is not added"),
        (
            "expect:\n  - {unit: u1, min_clearance_m: 1, to: e3}\n",
            "line 2, expect[0].to: 'e3' is never added",
        ),
        ("expect:\n  - {unit: u1}\n", "expect[0].arrives_within_s: give exactly one of"),
        (
            "timeline:\n  - do: wait\n    seconds: 1\n    at_s: 2\n    when: {unit: u1, within_m: 1, of: [0, 0]}\n",
            "line 5, timeline[0].when: give at_s or when, not both",
        ),
        ("timeline: [\n", "invalid YAML"),
    ],
)
def test_script_errors_name_the_line_and_field(tmp_path, body, message):
    p = tmp_path / "s.yaml"
    p.write_text(body)
    with pytest.raises(InputError) as info:
        load_script(p)
    assert message in str(info.value)


@pytest.mark.proc
def test_example_scripts_validate():
    scripts = sorted(EXAMPLES.glob("*inject*.yaml"))
    assert scripts
    for path in scripts:
        r = run_pfp("inject", str(path), "--check", timeout=30)
        assert r.returncode == 0, r.stderr


@pytest.mark.proc
def test_inject_says_which_entry_it_waits_on_and_for_what(tmp_path, mission):
    script = tmp_path / "wait.yaml"
    script.write_text(
        "duration_s: 3\ntimeline:\n"
        "  - {do: add_threat, threat: e1, position: [4, 6], sigma_range: 1.0, sigma_lateral: 0.7}\n"
        "  - {do: remove_threat, threat: e1, when: {unit: u9, within_m: 1, of: [5, 5]}}\n"
    )
    with planner_process(mission=mission) as (endpoint, _):
        r = run_pfp(
            "inject",
            str(script),
            "--connect",
            endpoint,
            "--mission",
            mission,
            "--progress-s",
            "0.5",
            timeout=60,
        )
    assert r.returncode == 1  # the trigger never came
    assert "waiting on timeline[1] (remove threat e1): u9 within 1 m of (5, 5), not seen yet" in r.stdout
    assert "FAIL  timeline[1] (remove threat e1) never fired" in r.stdout


ORIGIN_SCRIPT = """\
name: elsewhere
origin: {lat: -33.9, lon: 151.2}
timeline:
  - {do: add_threat, threat: t1, position: [4, 6], sigma_range: 1.0, sigma_lateral: 0.7}
  - {do: set_goal, unit: u1, position: {lat: -33.8999, lon: 151.2001},
     when: {unit: u1, within_m: 1, of: [1, 2]}}
  - {do: move_threat, threat: t1, position: [5, 6]}
"""


@pytest.mark.unit
def test_a_script_origin_other_than_the_planners_is_converted_exactly_and_none_is_refused(tmp_path):
    from pfp_clients.inject import script_in_planner_frame

    from pfp_service.geo import Origin

    path = tmp_path / "s.yaml"
    path.write_text(ORIGIN_SCRIPT)
    script = load_script(path)
    mine, theirs = Origin(lat=-33.9, lon=151.2), Origin(lat=-33.91, lon=151.19)
    moved, line = script_in_planner_frame(script, theirs, "m")
    assert line is not None and "-33.9,151.2" in line and "-33.91,151.19" in line
    new: list[Any] = list(moved.timeline)
    old: list[Any] = list(script.timeline)
    pairs = [
        (new[0].position, old[0].position),
        (new[1].position, old[1].position),
        (new[1].when.of, old[1].when.of),
        (new[2].position, old[2].position),
    ]
    for p, q in pairs:
        assert abs(p[0] - q[0]) > 500 or abs(p[1] - q[1]) > 500  # really moved: 0.01 degree away
        back = mine.to_local(*theirs.to_geodetic(*p))
        assert abs(back[0] - q[0]) < 1e-6 and abs(back[1] - q[1]) < 1e-6
    assert script_in_planner_frame(script, mine, "m") == (script, None)
    with pytest.raises(InputError, match="has none"):
        script_in_planner_frame(script, None, "m")
