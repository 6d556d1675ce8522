"""Threat shapes (``core.shapes``): the registry, each shape's value and gradient, and the wire's way in.

Every registered shape is checked the same way, so a new shape's module and
registry entry are covered here without a new test: its gradient against
central differences, its outline at its level, its description, and the
translation of a message of that shape.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pfp_clients.map.model import MapModel
from pfp_clients.map.samples import ThreatSeen

from pfp_service.core import ThreatField, shapes
from pfp_service.core.shapes import area, skew_normal
from pfp_service.core.threat import Threat
from pfp_service.errors import InputError
from pfp_service.geojson import zone_ring
from pfp_service.wire import PreviewRequest, RejectedEvent, ThreatUpdate, WhatIfThreat, decode_threat
from pfp_service.world import translate
from pfp_service.world.world import ThreatPut, World

pytestmark = pytest.mark.unit

# One message of every registered shape: a shape without one here fails test_every_shape_has_a_sample.
SAMPLES = {
    "skew_normal": ThreatUpdate(
        position=(3.0, -2.0), facing_deg=200.0, sigma_range=4.0, sigma_lateral=2.5, skew=3.0
    ),
    "area": ThreatUpdate(position=(3.0, -2.0), shape="area", params={"radius_m": 5.0}),
}


def test_every_shape_has_a_sample_and_the_default_is_the_skew_normal():
    assert set(SAMPLES) == set(shapes.SHAPES)
    assert (
        shapes.DEFAULT == "skew_normal" == ThreatUpdate(position=(0, 0), sigma_range=1, sigma_lateral=1).shape
    )
    for name, shape in shapes.SHAPES.items():
        assert shape.name == name and shape.summary
        names = [p.name for p in shape.params]
        assert len(names) == len(set(names)) and names


def test_an_unknown_shape_is_refused_by_name():
    with pytest.raises(ValueError, match=r"^shape: unknown threat shape 'cone' \(known: skew_normal, area\)"):
        shapes.get("cone")


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({}, r"^params\.radius_m: is required by the area shape"),
        ({"radius_m": 0.0}, r"^params\.radius_m: must be within"),
        ({"radius_m": math.inf}, r"^params\.radius_m: must be within"),
        ({"radius_m": 1.0, "r": 2.0}, r"^params\.r: not a parameter of the area shape"),
    ],
)
def test_parameters_are_checked_with_their_field(params, message):
    with pytest.raises(ValueError, match=message):
        shapes.check_params(area.SHAPE, params)


@pytest.mark.parametrize("name", list(SAMPLES))
@pytest.mark.parametrize("intensity", ["peak", "density"])
def test_value_and_gradient_agree_with_central_differences(name, intensity):
    threat = translate.threat(SAMPLES[name], "t")
    rng = np.random.default_rng(31)
    seed_note = "seed 31"
    pts = np.array(threat.xi) + rng.normal(scale=threat.max_sigma(), size=(64, 2))
    level, grad = shapes.evaluate(threat, pts, intensity)
    assert np.all(level >= 0.0) and np.all(np.isfinite(grad)), seed_note
    h = 1e-6 * threat.max_sigma()
    for axis in (0, 1):
        dx = np.zeros(2)
        dx[axis] = h
        up, _ = shapes.evaluate(threat, pts + dx, intensity)
        down, _ = shapes.evaluate(threat, pts - dx, intensity)
        np.testing.assert_allclose(grad[:, axis], (up - down) / (2 * h), rtol=1e-5, atol=1e-9 * level.max())


@pytest.mark.parametrize("name", list(SAMPLES))
def test_the_outline_lies_at_its_fraction_of_the_peak_and_inside_the_culling_box(name):
    update = SAMPLES[name]
    threat = translate.threat(update, "t")
    shape = shapes.get(name)
    peak_level = float(ThreatField([threat]).level(np.array(threat.mode())))
    for fraction in (0.1, 0.5):
        ring = np.array(shape.outline(threat, fraction, 24))
        at = ThreatField([threat]).level(ring)
        np.testing.assert_allclose(at / peak_level, fraction, rtol=2e-3)
        x0, y0, x1, y1 = shapes.reach_box(threat)
        assert (ring[:, 1] < y1).all()
        assert (ring[:, 0] > x0).all() and (ring[:, 0] < x1).all() and (ring[:, 1] > y0).all()


def test_the_area_circle_is_the_traced_level_set():
    threat = translate.threat(SAMPLES["area"], "t")
    circle = np.array(area.SHAPE.outline(threat, 0.1, 96))
    np.testing.assert_allclose(circle, zone_ring(threat, 0.1, 96), atol=2e-3)
    assert math.hypot(*(circle[0] - threat.xi)) == pytest.approx(5.0 * math.sqrt(2 * math.log(10)), abs=1e-3)


def test_an_area_packs_as_the_unskewed_round_skew_normal_it_is():
    got = ThreatField([translate.threat(SAMPLES["area"], "a")]).packed
    same = ThreatField([Threat.from_facing((3.0, -2.0), 0.0, 5.0, 5.0, 0.0, id="a")]).packed
    np.testing.assert_allclose(got, same, rtol=1e-12, atol=1e-15)


def test_a_message_without_a_shape_is_the_skew_normal_it_always_was():
    body = {"position": [4, 6], "facing_deg": 225, "sigma_range": 1.0, "sigma_lateral": 0.7, "skew": 2}
    update = decode_threat(json.dumps(body).encode())
    assert update.shape == "skew_normal"
    assert translate.threat(update, "e1") == Threat.from_facing((4, 6), 225, 1.0, 0.7, 2, id="e1")
    marks = skew_normal.SHAPE.marks(update.position, translate.shape_params(update))
    assert len(marks) == 2 and marks[0][0] == (4.0, 6.0)  # the arrow from the enemy, along its facing
    assert marks[0][1][0] < 4.0 and marks[0][1][1] < 6.0  # 225 degrees: south-west


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"position": [0, 0]}, "$.sigma_range"),
        ({"position": [0, 0], "sigma_range": 1}, "$.sigma_lateral"),
        ({"position": [0, 0], "sigma_range": 1, "sigma_lateral": 1, "params": {"radius_m": 1}}, "$.params"),
        ({"position": [0, 0], "shape": "Area!"}, "$.shape"),
    ],
)
def test_the_decoder_refuses_a_malformed_shape_with_its_field(body, field):
    with pytest.raises(InputError) as err:
        decode_threat(json.dumps(body).encode())
    assert err.value.path == field


def test_the_world_plans_round_an_area_and_refuses_an_unknown_shape_on_its_key():
    w = World()
    cone = ThreatUpdate(position=(0, 0), shape="cone", params={"half_angle_deg": 30})
    out = w.apply([ThreatPut("a1", SAMPLES["area"]), ThreatPut("c1", cone)], 0.0)
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert ev.key.endswith("/threat/c1") and ev.field == "$.shape" and "unknown threat shape" in ev.reason
    assert [t.id for t in w.field.threats] == ["a1"]
    out = w.apply([ThreatPut("a1", ThreatUpdate(position=(0, 0), shape="area", params={}))], 1.0)
    (ev,) = [e for e in out.events if isinstance(e, RejectedEvent)]
    assert ev.field == "$.params.radius_m"
    assert w.field.threats[0].omega == ((25.0, 0.0), (0.0, 25.0))  # the refused put left the area in force


def test_a_preview_refuses_a_what_if_of_unknown_shape_by_index_and_field():
    from pfp_service.world.preview import whatifs

    ok = WhatIfThreat(id="w0", position=(0, 0), shape="area", params={"radius_m": 2.0})
    req = PreviewRequest(threats=[ok, WhatIfThreat(id="w1", position=(0, 0), shape="cone")])
    with pytest.raises(InputError) as err:
        whatifs(req)
    assert err.value.path == "$.threats[1].shape"


def test_the_map_draws_what_the_shape_gives_and_skips_what_the_planner_refuses():
    m = MapModel()
    cone = ThreatUpdate(position=(0, 0), shape="cone")
    m.apply(
        [ThreatSeen("a1", SAMPLES["area"]), ThreatSeen("s1", SAMPLES["skew_normal"]), ThreatSeen("c1", cone)],
        0.0,
    )
    got = m.snapshot(0.0)["threats"]
    assert set(got) == {"a1", "s1"}
    a1, s1 = got["a1"], got["s1"]
    assert a1["marks"] == [] and len(s1["marks"]) == 2
    assert a1["rows"] == [("shape", "area"), ("radius", "5 m")]
    assert ("facing", "200°") in s1["rows"]
    radii = [math.hypot(x - 3.0, y + 2.0) for x, y in a1["zone"]]
    assert max(radii) - min(radii) < 2e-3  # a circle
    assert a1["update"]["params"] == {"radius_m": 5.0}  # what the page puts back when it moves it


AREA_SCENARIO = b"""
name: scout report
start: [0, 0]
goal: [20, 0]
threats:
  - {id: seen, position: [10, 0.5], shape: area, params: {radius_m: 2}}
"""


def test_a_scenario_file_takes_an_area_and_the_plan_goes_round_it():
    from pfp_service.core import plan
    from pfp_service.scenario import decode_scenario

    sc = decode_scenario(AREA_SCENARIO, "yaml")
    (threat,) = [s.threat for s in sc.schedule()]
    assert threat.omega == ((4.0, 0.0), (0.0, 4.0)) and threat.id == "seen"
    result = plan(sc.start, sc.goal, sc.schedule(), sc.planner.to_params())
    assert result.status == "reached" and min(y for _, y in result.path) < -1.0  # round the circle's south


@pytest.mark.parametrize(
    ("threat", "field"),
    [
        ("{position: [1, 1], shape: area}", "params.radius_m"),
        ("{position: [1, 1], shape: area, params: {radius_m: 2}, sigma_range: 1}", "shape"),
        ("{position: [1, 1], shape: cone}", "shape"),
        ("{position: [1, 1], sigma_range: 1, sigma_lateral: 1, params: {radius_m: 2}}", "params"),
    ],
)
def test_a_scenario_refuses_a_bad_shape_with_its_field(threat, field):
    from pfp_service.scenario import decode_scenario

    doc = b"start: [0, 0]\ngoal: [5, 5]\nthreats:\n  - " + threat.encode() + b"\n"
    with pytest.raises(InputError) as err:
        decode_scenario(doc, "yaml")
    assert err.value.path == f"threats[0].{field}"  # a file's paths have no $


def test_an_injection_script_adds_an_area_and_refuses_an_unknown_shape(tmp_path):
    from pfp_clients.script import AddThreat, load_script

    good = tmp_path / "good.yaml"
    good.write_text(
        "duration_s: 10\ntimeline:\n  - {do: add_threat, threat: s1, position: [4, 6], shape: area, params: {radius_m: 3}}\n"
    )
    (step,) = load_script(good).timeline
    assert isinstance(step, AddThreat) and translate.threat(step.update(), "s1").omega == (
        (9.0, 0.0),
        (0.0, 9.0),
    )
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "duration_s: 10\ntimeline:\n  - {do: add_threat, threat: s1, position: [4, 6], shape: cone}\n"
    )
    with pytest.raises(InputError, match="unknown threat shape 'cone'"):
        load_script(bad)


def test_the_threat_kind_refuses_a_shape_it_cannot_plan_before_it_is_stored():
    from pfp_service.world.kinds import BY_INPUT

    kind = BY_INPUT[ThreatPut]
    put = kind.make(
        "a1",
        False,
        json.dumps({"position": [1, 2], "shape": "area", "params": {"radius_m": 3}}).encode(),
        None,
        None,
    )
    assert isinstance(put, ThreatPut) and put.update.params == {"radius_m": 3.0}
    with pytest.raises(InputError) as err:
        kind.make("c1", False, b'{"position": [1, 2], "shape": "cone"}', None, None)
    assert err.value.path == "$.shape"
    with pytest.raises(InputError) as err:
        kind.make(
            "a2", False, b'{"position": [1, 2], "shape": "area", "params": {"radius_m": -1}}', None, None
        )
    assert err.value.path == "$.params.radius_m"
