"""Output for people: positions in lat/lon, MGRS or metres (``coords``), natural sort, the human log,
plain ``--help`` with an example per command, the plot's lat/lon ticks, and ``pfp bench --check``."""

from __future__ import annotations

import io
import json
import logging
import re
import shlex

import mgrs
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks._check import exit_code
from pfp_service.coords import Coords, degrees, metres_offset
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.natsort import natural_key, natural_sorted
from tests.conftest import EXAMPLES, run_pfp

ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=90.0)
LATLON = re.compile(r"(\d+\.\d{5})([NS]) (\d+\.\d{5})([EW])")


def _parse_degrees(text: str) -> tuple[float, float]:
    m = LATLON.search(text)
    assert m is not None, text
    lat = float(m[1]) * (1 if m[2] == "N" else -1)
    lon = float(m[3]) * (1 if m[4] == "E" else -1)
    return lat, lon


@pytest.mark.unit
@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-20_000, 20_000),
    y=st.floats(-20_000, 20_000),
    lat0=st.floats(-70, 70),
    lon0=st.floats(-179, 179),
)
def test_latlon_text_reads_back_to_the_point_within_a_metre(x, y, lat0, lon0):
    origin = Origin(lat=lat0, lon=lon0)
    text = Coords.choose("latlon", origin).point((x, y))
    lat, lon = _parse_degrees(text)
    back = origin.to_local(lat, lon)
    # 5 decimals: half of 1e-5 degrees is at most 0.56 m north and 0.56 cos(lat) m east
    assert abs(back[0] - x) < 0.6 and abs(back[1] - y) < 0.6, (text, back)
    assert f"({metres_offset(x, y)})" in text


@pytest.mark.unit
@settings(max_examples=40, deadline=None)
@given(x=st.floats(-20_000, 20_000), y=st.floats(-20_000, 20_000))
def test_mgrs_text_is_the_grid_reference_of_the_point(x, y):
    text = Coords.choose("mgrs", ORIGIN).point((x, y), offset=False)
    zone, easting, northing = text.split(" ")
    assert len(easting) == 5 and len(northing) == 5
    lat, lon = mgrs.MGRS().toLatLon(zone + easting + northing)
    back = ORIGIN.to_local(lat, lon)
    # a 1 m reference names the square's south-west corner: within sqrt(2) m of the point
    assert abs(back[0] - x) < 1.5 and abs(back[1] - y) < 1.5, (text, back)


@pytest.mark.unit
def test_the_default_is_latlon_with_an_origin_and_metres_without():
    assert Coords.choose(None, ORIGIN).style == "latlon"
    assert Coords.choose(None, None).point((300.0, 260.0)) == "(300.0, 260.0)"
    assert Coords.choose("metres", ORIGIN).point((300.0, 260.0)) == "(300.0, 260.0)"
    text = Coords.choose(None, ORIGIN).point((300.0, 260.0))
    assert text == f"{degrees(*ORIGIN.to_geodetic(300.0, 260.0))} (300 m E, 260 m N)"
    assert metres_offset(-5.24, -260.4) == "5.2 m W, 260 m S"
    assert metres_offset(0.0, 0.0) == "the origin"
    assert degrees(-33.9, -70.6) == "33.90000S 70.60000W"


@pytest.mark.unit
def test_a_geodetic_style_without_an_origin_is_refused_or_falls_back_to_metres():
    with pytest.raises(InputError) as err:
        Coords.choose("mgrs", None)
    assert err.value.path == "--coords" and "origin" in err.value.reason
    assert Coords.choose("latlon", None, strict=False).style == "metres"
    # a table of many points converts at once and keeps the order
    pts = [(float(i), float(-i)) for i in range(50)]
    many = Coords.choose("latlon", ORIGIN).points(pts)
    assert many == [Coords.choose("latlon", ORIGIN).point(p) for p in pts]


@pytest.mark.unit
def test_natural_sort_counts_numbers():
    assert natural_sorted(["m10", "m2", "m1", "r1", "m11", "M3"]) == ["m1", "m2", "M3", "m10", "m11", "r1"]
    assert natural_sorted(["planner-10", "planner-9"]) == ["planner-9", "planner-10"]
    assert natural_key("a01") == natural_key("a1")  # the same number
    assert sorted(["b", "10", "a2"], key=natural_key) == ["10", "a2", "b"]  # numbers first, never a TypeError


@pytest.mark.unit
def test_the_human_log_prints_values_in_lat_lon_and_json_keeps_numbers():
    import msgspec

    from pfp_service.node.log import get_logger, log_changes, setup_logging
    from pfp_service.wire.messages import ArrivedEvent, Goal, ReplanEvent, ThreatChange, ThreatUpdate
    from pfp_service.world.events import GoalSet, ThreatPut

    changes = [
        ThreatPut("e1", ThreatUpdate(position=(300.0, 260.0), sigma_range=10.0, sigma_lateral=8.0)),
        GoalSet("m1", Goal(position=(1800.123456789, 1400.0))),
    ]
    replan = ReplanEvent(
        units=["m1"],
        reason="threats changed",
        changes=[ThreatChange(threat="e1", change="put", position=(300.0, 260.0))],
    )
    arrived = ArrivedEvent(
        unit="m1", position=(1799.9999999, 1400.333333333), distance_to_goal=3.2099999999999866
    )
    lines = {}
    for fmt in ("human", "json"):
        setup_logging(fmt, "info", Coords.choose(None, ORIGIN))
        root = logging.getLogger("pfp")
        out = io.StringIO()
        root.handlers[0].setStream(out)  # type: ignore[attr-defined]
        log = get_logger("test")
        log_changes(log, changes)
        for ev in (replan, arrived):
            fields = {k: v for k, v in msgspec.structs.asdict(ev).items() if k not in ("t", "planner")}
            log.info(ev.__struct_config__.tag, extra={"fields": fields})
        lines[fmt] = out.getvalue().splitlines()
    human = "\n".join(lines["human"])
    assert "threat e1 put at 58.41283N 15.62643E (300 m E, 260 m N)" in human
    assert "goal of m1 set to " in human and "(1800 m E, 1400 m N)" in human
    assert "changes=[e1 put at 58.41283N 15.62643E (300 m E, 260 m N)]" in human
    assert "distance_to_goal=3.21" in human
    assert "ThreatChange(" not in human and "3.2099" not in human and "1400.33" not in human
    docs = [json.loads(line) for line in lines["json"]]
    assert docs[0]["msg"] == "threat put" and docs[0]["position"] == [300.0, 260.0]
    assert abs(docs[0]["lat"] - ORIGIN.to_geodetic(300.0, 260.0)[0]) < 1e-6
    assert docs[1]["msg"] == "goal set" and docs[1]["goal"] == [1800.123456789, 1400.0]
    assert docs[3]["distance_to_goal"] == 3.2099999999999866  # machines get the number as it is
    logging.getLogger("pfp").handlers.clear()


def _parsers():
    from pfp_service.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        yield name, p
        inner = [a for a in p._actions if isinstance(a, type(sub))]
        for a in inner:
            for inner_name, q in a.choices.items():
                yield f"{name} {inner_name}", q
    yield "", parser


@pytest.mark.unit
def test_help_is_plain_text_with_an_example_line_that_parses():
    from pfp_service.cli import build_parser

    parser = build_parser()
    missing = []
    for name, p in _parsers():
        text = p.format_help()
        assert "``" not in text, f"pfp {name} --help shows doc markup"
        example = text.rsplit("example:\n", 1)
        if len(example) != 2:
            if name.startswith("state "):  # the subcommands of `pfp state` share its example
                continue
            missing.append(name)
            continue
        for line in example[1].strip().splitlines():
            words = shlex.split(line)
            assert words[0] == "pfp", line
            if words[1:] == ["COMMAND", "--help"]:
                continue
            parser.parse_args(words[1:])  # exits 2 (SystemExit) on an example that does not parse
    assert not missing, f"commands without an example line in --help: {missing}"


@pytest.mark.unit
def test_bench_check_maps_missed_targets_to_exit_1():
    assert exit_code([True, True], check=True) == 0
    assert exit_code([True, False], check=True) == 1
    assert exit_code([True, None], check=True) == 0  # not measured is not missed
    assert exit_code([False], check=False) == 0  # without --check a measurement exits 0


@pytest.mark.proc
def test_bench_engine_check_exits_1_iff_a_target_is_missed():
    r = run_pfp("bench", "engine", "--quick", "--no-scale", "--repeat", "3", "--baseline-repeat", "1", "--check",
                timeout=600)  # fmt: skip
    verdicts = re.findall(r"^\s+\[(ok|MISSED)\] ", r.stdout, re.M)
    assert len(verdicts) >= 5, r.stdout + r.stderr
    assert r.returncode == (1 if "MISSED" in verdicts else 0), (r.returncode, verdicts, r.stderr[-2000:])


@pytest.mark.unit
def test_the_plot_axes_are_longitude_and_latitude_at_round_values(monkeypatch, tmp_path):
    pytest.importorskip("matplotlib")
    from pfp_service.core import plan
    from pfp_service.render import plots
    from pfp_service.scenario import load_scenario

    scenario = load_scenario(EXAMPLES / "geo-simple.yaml")
    result = plan(scenario.start, scenario.goal, scenario.schedule(), scenario.planner.to_params())
    seen = {}

    def keep(fig, out, what):
        ax = fig.axes[0]
        seen["x"] = [(t.get_position()[0], t.get_text()) for t in ax.get_xticklabels()]
        seen["y"] = [(t.get_position()[1], t.get_text()) for t in ax.get_yticklabels()]
        seen["box"] = (*ax.get_xlim(), *ax.get_ylim())
        seen["labels"] = (ax.get_xlabel(), ax.get_ylabel())

    monkeypatch.setattr(plots, "save_png", keep)
    plots.plot_plan(scenario, result, tmp_path / "p.png", Coords.choose(None, scenario.origin))
    assert "longitude" in seen["labels"][0] and "latitude" in seen["labels"][1]
    x0, _x1, y0, _y1 = seen["box"]
    assert len(seen["x"]) >= 3 and len(seen["y"]) >= 3
    for x, text in seen["x"]:
        assert text.endswith("°E"), text
        _lat, lon = scenario.origin.to_geodetic(x, y0)  # where the tick meets the bottom edge
        assert abs(lon - float(text[:-2])) < 1e-7, (x, text, lon)
    for y, text in seen["y"]:
        assert text.endswith("°N"), text
        lat, _lon = scenario.origin.to_geodetic(x0, y)
        assert abs(lat - float(text[:-2])) < 1e-7, (y, text, lat)
