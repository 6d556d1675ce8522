"""Hostile files: each reader refuses past a bound of ``bounds.LIMITS`` with one line naming the file and
the limit, quickly and in bounded memory (alias bombs, deep nesting, huge GeoJSON, deep TOML)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pfp_service import bounds
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from tests.conftest import ROOT

ORIGIN = Origin(lat=58.4105, lon=15.6213)
DEEP = 100_000


def _bomb(levels: int, top: str, tail: str = "") -> str:
    """A billion-laughs document: each anchor is nine aliases of the one before it."""
    lines = [top, 'a0: &a0 ["x","x","x","x","x","x","x","x","x"]']
    lines += [f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\n" + tail


def _threat_bomb(levels: int) -> str:
    lines = ["start: [0, 0]", "goal: [10, 10]", "threats:"]
    lines.append("  - &a0 {position: [1, 1], sigma_range: 1, sigma_lateral: 1}")
    lines += [f"  - &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\n"


def _ring(n: int) -> list[list[float]]:
    # numpy, not a comprehension of math.cos and round: 800,000 points in a fraction of a second
    turn = 2 * np.pi * np.arange(n) / n
    xs = np.round(15.6213 + 0.01 * np.cos(turn), 5)
    ys = np.round(58.4105 + 0.01 * np.sin(turn), 5)
    ring = np.column_stack([xs, ys]).tolist()
    return [*ring, ring[0]]


def _collection(*rings: list[list[float]]) -> str:
    feats = [
        {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [r]}}
        for r in rings
    ]
    return json.dumps({"type": "FeatureCollection", "features": feats}, separators=(",", ":"))


def _many_squares(n: int) -> str:
    k = np.arange(n)
    xs, ys = np.round(15.6 + (k % 300) * 0.0002, 4), np.round(58.40 + (k // 300) * 0.0002, 4)
    x1, y1 = np.round(xs + 0.0001, 4), np.round(ys + 0.0001, 4)
    corners = np.stack([xs, ys, x1, ys, x1, y1, xs, ys], axis=1).reshape(n, 4, 2).tolist()
    return _collection(*corners)


# The files past the budget are built by repeating a small one's text: the scan counts positions
# whatever their values, and rendering 800,000 floats with json.dumps cost each test 1.5 s of CPU.
def _big_ring(blocks: int, *, closed: bool) -> str:
    """One polygon of ``blocks`` turns of a 1,000-point ring, closed or not: a 16 MB file."""
    turn = json.dumps(_ring(1_000)[:-1], separators=(",", ":"))[1:-1]
    coords = ",".join([turn] * blocks) + ("," + turn.split("],", 1)[0] + "]" if closed else "")
    return _collection([[0.0, 0.0]]).replace("[[[0.0,0.0]]]", "[[" + coords + "]]")


def _repeat_features(collection: str, times: int) -> str:
    """``collection`` with its features listed ``times`` times over."""
    head, feats = collection.split('"features":[', 1)
    return head + '"features":[' + ",".join([feats.removesuffix("]}")] * times) + "]}"


def _refused(load, path: Path) -> str:
    # CPU time, not wall: the refusal's work is what is bounded, and on the shared 2-core
    # machine at a load of 10 a 0.3 s scan took 4.8 s of wall time
    t0 = time.process_time()
    with pytest.raises(InputError) as got:
        load(path)
    took = time.process_time() - t0
    text = str(got.value)
    assert "\n" not in text and path.name in text, text
    assert took < 2.0, f"{path.name}: refused after {took:.2f} s of CPU"
    return text


def _scenario(p):
    from pfp_service.scenario import load_scenario

    return load_scenario(p)


def _team(p):
    from pfp_service.team import load_team

    return load_team(p)


def _script(p):
    from pfp_clients.script import load_script

    return load_script(p)


def _zones(p):
    from pfp_service.geojson import load_zones

    return load_zones(p, ORIGIN)


def _toml(p):
    from pfp_service.node.config import load_config

    return load_config(p, {}, {})


@pytest.mark.unit
def test_the_docs_show_the_one_table_of_limits():
    text = (ROOT / "docs" / "operations.md").read_text()
    assert bounds.table() in text, "docs/operations.md: paste bounds.table() in, as it is now"


@pytest.mark.unit
@pytest.mark.parametrize(
    ("name", "text", "load"),
    [
        ("s.yaml", _bomb(8, "start: [0, 0]\ngoal: [10, 10]"), _scenario),
        ("s.yaml", _threat_bomb(9), _scenario),
        ("team.yaml", _bomb(8, "name: t", "units: []\n"), _team),
        ("inject.yaml", _bomb(8, "name: i", "timeline: []\n"), _script),
    ],
)
def test_an_alias_bomb_is_refused_before_it_is_built(tmp_path, name, text, load):
    p = tmp_path / name
    p.write_text(text)
    assert len(text) < 600
    assert "(yaml_nodes)" in _refused(load, p)


@pytest.mark.unit
def test_a_recursive_alias_and_too_many_aliases_are_refused(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("start: [0, 0]\ngoal: [10, 10]\nx: &a [1, *a]\n")
    assert "names no complete node" in _refused(_scenario, p)
    p.write_text("start: &p [0, 0]\ngoal: [10, 10]\nx: [" + ", ".join(["*p"] * 1001) + "]\n")
    assert "(yaml_aliases)" in _refused(_scenario, p)


@pytest.mark.unit
def test_anchors_within_the_bounds_still_work(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text(
        "start: [0, 0]\ngoal: [100, 100]\nthreats:\n"
        "  - &t {id: a, position: [50, 40], sigma_range: 5, sigma_lateral: 5}\n"
        "  - {<<: *t, id: b, position: [20, 70]}\n"
    )
    s = _scenario(p)
    assert [t.id for t in s.threats] == ["a", "b"] and s.threats[1].sigma_range == 5


@pytest.mark.unit
@pytest.mark.parametrize(
    ("name", "text", "load"),
    [
        ("deep.yaml", "start: [0, 0]\ngoal: [1, 1]\nx: " + "[" * DEEP + "]" * DEEP + "\n", _scenario),
        (
            "deep-block.yaml",
            "start: [0, 0]\ngoal: [1, 1]\nx:\n" + "".join(" " * i + "- \n" for i in range(200)),
            _scenario,
        ),
        ("deep.json", '{"start": [0, 0], "goal": [1, 1], "x": ' + "[" * DEEP + "]" * DEEP + "}", _scenario),
        ("team.yaml", "name: d\nunits: " + "[" * DEEP + "]" * DEEP + "\n", _team),
        (
            "deep.geojson",
            '{"type": "FeatureCollection", "features": ' + "[" * DEEP + "]" * DEEP + "}",
            _zones,
        ),
        ("deep.toml", "x = " + "[" * DEEP + "]" * DEEP + "\n", _toml),
        ("dotted.toml", "x" + ".y" * 100 + " = 1\n", _toml),
        ("tables.toml", "[" + ".".join(["t"] * 100) + "]\nx = 1\n", _toml),
    ],
)
def test_deep_nesting_is_one_line_naming_the_limit(tmp_path, name, text, load):
    p = tmp_path / name
    p.write_text(text)
    assert "nested deeper than 64 levels (depth)" in _refused(load, p)


@pytest.mark.unit
def test_strings_holding_brackets_are_not_nesting(tmp_path):
    bounds.scan_json('{"a\\\\": "x[[[\\"[[", "b": [1, [2]], "c": "]]]]"}', "t.json", positions=2)
    bounds.scan_toml("a = \"[[[[\" # [[[[\nb = '''\n[[[['''\nc = [[1], [2]]\n", "t.toml")
    with pytest.raises(InputError, match="holds 3 positions"):
        bounds.scan_json('{"b": [1, [2], [-3]]}', "t.json", positions=2)


@pytest.mark.unit
@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("ring.geojson", lambda: _big_ring(800, closed=True)),
        ("open-ring.geojson", lambda: _big_ring(800, closed=False)),
        ("squares.geojson", lambda: _repeat_features(_many_squares(1_000), 100)),
    ],
)
def test_a_zones_file_past_its_position_budget_is_refused_before_the_parse(tmp_path, monkeypatch, name, text):
    p = tmp_path / name
    p.write_text(text())
    assert p.stat().st_size > 12 * 1024 * 1024
    monkeypatch.setattr(json, "loads", lambda *a, **k: pytest.fail("parsed a file past its budget"))
    assert "(json_positions)" in _refused(_zones, p)


@pytest.mark.unit
def test_a_json_scenario_past_its_position_budget_is_refused(tmp_path):
    p = tmp_path / "s.json"
    zone = {"polygon": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}
    p.write_text(json.dumps({"start": [0, 0], "goal": [5, 5], "zones": [zone] * 20_000}))
    assert "(json_positions)" in _refused(_scenario, p)


@pytest.mark.unit
def test_a_zones_file_at_its_budget_loads_and_an_error_line_needs_no_yaml(tmp_path, monkeypatch):
    import yaml

    n = bounds.limit("json_positions") // 16 - 1
    p = tmp_path / "full.geojson"
    p.write_text(_collection(*[_ring(n)] * 16).replace("},{", "},\n{"))
    assert len(_zones(p)) == 16  # its time is a benchmark's to judge, not a test's
    monkeypatch.setattr(yaml, "compose", lambda *a, **k: pytest.fail("the error path parsed JSON as YAML"))
    monkeypatch.setattr(yaml, "parse", lambda *a, **k: pytest.fail("the error path parsed JSON as YAML"))
    bad = tmp_path / "bad.geojson"
    first, rest = p.read_text().split("\n", 1)
    bad.write_text(first + "\n" + rest.replace('"Polygon"', '"Point"', 1))
    assert "line 2, features[1].geometry" in _refused(_zones, bad)


@pytest.mark.unit
def test_json_line_of_finds_a_field_as_the_yaml_tree_did():
    text = '{"a": 1,\n "b": [\n {"c": 2},\n {"d":\n  [3, {"e": "x,]}"}]}]}'
    assert bounds.json_line_of(text, "b[1].d") == 5
    assert bounds.json_line_of(text, "b[0].c") == 3
    assert bounds.json_line_of(text, "b[1].zz") == 4  # the nearest parent
    assert bounds.json_line_of(text, "") == 1


# -- the CLI, as an attacker runs it: exit 2, one line, in time and memory ---------------------------------

# The peak RSS of this process image: /proc's VmHWM, not ru_maxrss, which Linux carries over from
# the forked copy of the parent (the test runner, hundreds of MB) across the exec.
_WRAP = """
import sys, time
t0 = time.perf_counter()
from pfp_service.cli import main
try:
    code = main(sys.argv[2:])
finally:
    hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0].split()[1]
    with open(sys.argv[1], "w") as f:
        f.write(f"{int(hwm) / 1024:.0f} {time.perf_counter() - t0:.2f}")
sys.exit(code)
"""


def _run(tmp_path: Path, *args: str) -> tuple[subprocess.CompletedProcess[str], float, float]:
    """``pfp ARGS`` in a subprocess: the result, its peak RSS in MB and its seconds."""
    out = tmp_path / "peak.txt"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    r = subprocess.run(
        [sys.executable, "-c", _WRAP, str(out), *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        env=env,
    )
    mb, seconds = out.read_text().split()
    return r, float(mb), float(seconds)


@pytest.fixture(scope="module")
def baseline(tmp_path_factory) -> tuple[float, float]:
    """What ``pfp plan`` costs on a good two-line scenario: the CLI's own imports (numba's LLVM is most)."""
    tmp = tmp_path_factory.mktemp("base")
    ok = tmp / "ok.yaml"
    ok.write_text("start: [0, 0]\ngoal: [1, 1]\nplanner: {max_iter: 1}\n")
    r, mb, seconds = _run(tmp, "plan", str(ok))
    assert r.returncode in (0, 1), r.stderr
    return mb, seconds


@pytest.mark.proc
@pytest.mark.parametrize(
    ("name", "text", "command", "limit"),
    [
        ("bomb8.yaml", _bomb(8, "start: [0, 0]\ngoal: [10, 10]"), ["plan"], "yaml_nodes"),
        ("bomb9.yaml", _threat_bomb(9), ["plan"], "yaml_nodes"),
        ("team.yaml", _bomb(8, "name: t", "units: []\n"), ["acl", "--out", "{tmp}/acl"], "yaml_nodes"),
        ("inject.yaml", _bomb(8, "name: i", "timeline: []\n"), ["inject", "--check"], "yaml_nodes"),
        ("deep.yaml", "start: [0, 0]\ngoal: [1, 1]\nx: " + "[" * DEEP + "]" * DEEP + "\n", ["plan"], "depth"),
        ("deep.json", '{"start": [0, 0], "goal": [1, 1], "x": ' + "[" * DEEP + "]" * DEEP + "}", ["plan"], "depth"),
        ("deep-team.yaml", "name: d\nunits: " + "[" * DEEP + "]" * DEEP + "\n", ["acl", "--out", "{tmp}/acl"], "depth"),
        ("deep.toml", "x = " + "[" * DEEP + "]" * DEEP + "\n", ["serve", "--config"], "depth"),
        ("ring.geojson", lambda: _collection(_ring(800_000)), ["plan", "examples/geo-simple.yaml", "--zones"], "json_positions"),
        ("squares.geojson", lambda: _many_squares(100_000), ["plan", "examples/geo-simple.yaml", "--zones"], "json_positions"),
        ("deep.geojson", '{"features": ' + "[" * DEEP + "]" * DEEP + "}", ["plan", "examples/geo-simple.yaml", "--zones"], "depth"),
        ("big.yaml", "start: [0, 0]\ngoal: [1, 1]\nthreats:\n" + "  - {position: [1, 1], sigma_range: 1, sigma_lateral: 1}\n" * 40_000, ["plan"], "(yaml_bytes)"),
    ],
)  # fmt: skip
def test_the_cli_refuses_a_hostile_file_in_one_line_in_time_and_memory(
    tmp_path, baseline, name, text, command, limit
):
    p = tmp_path / name
    p.write_text(text() if callable(text) else text)  # the big ones are built here, not at collection
    args = [a.format(tmp=tmp_path) for a in command]
    r, mb, seconds = _run(tmp_path, *args, str(p))
    base_mb, base_s = baseline
    print(
        f"{name}: exit {r.returncode}, {seconds:.2f} s (baseline {base_s:.2f}), {mb:.0f} MB (baseline {base_mb:.0f})"
    )
    assert r.returncode == 2, r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and name in lines[0] and limit in lines[0], r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert seconds <= base_s + 2.0, f"{seconds:.2f} s against {base_s:.2f} s for a good file"
    assert mb <= base_mb + 64, f"{mb:.0f} MB against {base_mb:.0f} MB for a good file"
