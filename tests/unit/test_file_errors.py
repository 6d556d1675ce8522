"""Every file error names the file and the line of the bad field: scenario (YAML and JSON), team,
inject script and GeoJSON zones files, each read as the CLI reads it."""

from __future__ import annotations

import pytest

from pfp_service.errors import InputError
from pfp_service.geo import Origin

pytestmark = pytest.mark.unit

ORIGIN = Origin(lat=58.4105, lon=15.6213)


def _error(load, path) -> str:
    with pytest.raises(InputError) as err:
        load(path)
    return f"{err.value.path}: {err.value.reason}"


def test_scenario_files_yaml_and_json(tmp_path):
    from pfp_service.scenario import load_scenario

    bad = tmp_path / "s.yaml"
    bad.write_text(
        "name: s\nstart: [0, 0]\ngoal: [10, 10]\nthreats:\n  - {id: e1, position: [5, 5], sigma_range: 0, sigma_lateral: 1}\n"
    )
    assert _error(load_scenario, bad).startswith("s.yaml line 5, threats[0].sigma_range: ")
    bad = tmp_path / "s.json"
    bad.write_text('{"name": "s",\n "start": [0, 0],\n "goal": [10, "a"]}\n')
    assert _error(load_scenario, bad).startswith("s.json line 3, goal[1]: ")
    bad.write_text('{"name": "s",\n "start": [0, 0],\n x}\n')
    assert _error(load_scenario, bad).startswith("s.json line 3: malformed JSON")
    bad.write_text('{"name": "s",\n "start": [0, 0\n')
    assert _error(load_scenario, bad).startswith("s.json line 2: malformed JSON")


def test_team_and_inject_files(tmp_path):
    from pfp_clients.script import load_script

    from pfp_service.team import load_team

    team = tmp_path / "team.yaml"
    team.write_text(
        "name: t\nunits:\n  - {id: m1, kind: manned, start: [0, 0], goal: [10, x], speed_mps: 1}\n"
    )
    assert _error(load_team, team).startswith("team.yaml line 3, units[0].goal[1]: ")
    script = tmp_path / "inject.yaml"
    script.write_text(
        "timeline:\n  - {do: wait, seconds: 1}\n"
        "  - {do: add_threat, threat: e1, position: [1, 2], sigma_range: -1, sigma_lateral: 1}\n"
    )
    assert _error(load_script, script).startswith("inject.yaml line 3, timeline[1].sigma_range: ")


def test_zones_geojson_files(tmp_path):
    from pfp_service.geojson import load_zones

    bad = tmp_path / "z.geojson"
    bad.write_text(
        '{"type": "FeatureCollection",\n "features": [\n'
        '  {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[[15.63, 58.41], [15.631, 58.4101], [15.632, 58.412], [15.63, 58.41]]]}},\n'
        '  {"type": "Feature",\n   "geometry": {"type": "Point", "coordinates": [15.6, 58.4]}}\n ]}\n'
    )
    text = _error(lambda p: load_zones(p, ORIGIN), bad)
    assert text.startswith(f"{bad} line 5, features[1].geometry: "), text
    bad.write_text('{"type": "FeatureCollection",\n "features": [\n  {}\n  {}\n ]}\n')
    assert "line 4" in _error(lambda p: load_zones(p, ORIGIN), bad)
