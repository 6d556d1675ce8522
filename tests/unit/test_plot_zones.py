"""Plots show everything that shaped the path: zones, lat/lon axes with an origin, pop-ups from when they appeared.

Checked on the figure's own artists (``plots.plan_figure`` and ``tracks.tracks_figure``
return the figure before it is written): each keep-out zone is a patch whose gid
is ``zone:ID``, labelled ``ID (no-go)``; the report's figure of a record with an
origin has longitude and latitude axes, draws a threat put mid-run as a pop-up
labelled with when it appeared, on the units' own (simulated) clock, and the
table's times are on that clock.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("matplotlib")

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
from pfp_clients.record.mcapfile import Entry, Record
from pfp_clients.record.report import clock_name, popups, summarise, zones_at_end

from pfp_service.coords import Coords
from pfp_service.core import plan
from pfp_service.geo import Origin
from pfp_service.geojson import load_zones
from pfp_service.render.plots import plan_figure
from pfp_service.render.tracks import tracks_figure
from pfp_service.scenario import load_scenario
from pfp_service.wire import keys

pytestmark = pytest.mark.unit
ROOT = Path(__file__).resolve().parents[2]
S = 1_000_000_000


def _zone_patches(fig) -> dict[str, object]:
    return {
        p.get_gid()[5:]: p for ax in fig.axes for p in ax.patches if (p.get_gid() or "").startswith("zone:")
    }


def _texts(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def test_a_plan_plot_draws_the_scenarios_zones_and_the_zones_file():
    sc = load_scenario(ROOT / "examples" / "zones.yaml")
    zones = sc.zone_set().plus(load_zones(str(ROOT / "examples" / "minefield.geojson"), sc.origin))
    result = plan(sc.start, sc.goal, sc.schedule(), sc.planner.to_params(), sc.bounds_tuple(), zones=zones)
    fig = plan_figure(sc, result, Coords.choose(None, sc.origin), list(zones))
    try:
        drawn = _zone_patches(fig)
        assert set(drawn) == {z.id for z in zones} == {"minefield", "crater", "wire-obstacle"}
        crater = zones.get("crater")
        assert crater is not None and crater.centre is not None
        assert drawn["crater"].center == pytest.approx(crater.centre)  # a circle, where it is
        x0, y0, x1, y1 = zones.get("minefield").bounds()
        ext = drawn["minefield"].get_path().get_extents()
        assert (ext.x0, ext.y0, ext.x1, ext.y1) == pytest.approx((x0, y0, x1, y1))
        assert {"minefield (no-go)", "crater (no-go)", "wire-obstacle (no-go)"} <= set(_texts(fig))
        legend = [t.get_text() for t in fig.legends[0].get_texts()] if fig.legends else []
        legend += [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]
        assert "keep-out zone (no-go)" in legend
    finally:
        plt.close(fig)
    plain = plan(sc.start, sc.goal, sc.schedule(), sc.planner.to_params(), sc.bounds_tuple())
    fig = plan_figure(sc, plain, None, [])  # told there are none: none drawn
    try:
        assert _zone_patches(fig) == {}
    finally:
        plt.close(fig)


def _report_record() -> Record:
    """Two units at x30: 10 s of record are 300 s on their clocks; a threat pops up 5 s (150 s) in; one zone."""
    origin = Origin(lat=58.4105, lon=15.6213, alt=90.0)
    m = "r1"
    threat = {"position": [150.0, 60.0], "sigma_range": 20.0, "sigma_lateral": 10.0}
    zone = {"circle": {"centre": [100.0, -40.0], "radius_m": 15.0}}
    entries = [Entry(0, keys.zone(m, "pond"), json.dumps(zone).encode())]
    for i in range(11):
        for uid, y in (("u1", 0.0), ("u2", 20.0)):
            state = {"position": [30.0 * i, y], "seq": i, "t": 30.0 * i}
            entries.append(Entry(i * S + 1, keys.shard_state(m, uid), json.dumps(state).encode()))
    entries.append(Entry(5 * S, keys.threat(m, "popper"), json.dumps(threat).encode()))
    direction = {"unit": "u1", "seq": 10, "status": "arrived", "vector": [0, 0]}
    entries.append(Entry(10 * S + 2, keys.unit_direction(m, "u1"), json.dumps(direction).encode()))
    return Record(m, origin, sorted(entries, key=lambda e: e.t_ns), [])


def test_the_report_figure_has_lat_lon_axes_zones_and_a_popup_from_when_it_appeared_on_the_unit_clock():
    rec = _report_record()
    rows, watch = summarise(rec)
    u1 = next(u for u in rows if u.unit == "u1")
    assert u1.time_s == pytest.approx(300.0)  # the unit's simulated seconds, not the record's 10
    assert clock_name(rows).startswith("the units' own clocks")
    appeared = popups(rows, watch)
    assert appeared == {"popper": "appeared at 150 s"}
    zones = zones_at_end(rec)
    assert [z.id for z in zones] == ["pond"]
    latest = [v.threat() for v in watch.versions]
    tracks = {u.unit: [(x, y) for _t, x, y in u.track] for u in rows}
    fig = tracks_figure(
        latest, "peak", tracks, {}, coords=Coords.choose("latlon", rec.origin), zones=zones, popups=appeared
    )
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel() == "longitude (WGS-84)" and ax.get_ylabel() == "latitude (WGS-84)"
        assert all(t.get_text().endswith("°E") for t in ax.get_xticklabels() if t.get_text())
        assert "popper (appeared at 150 s)" in _texts(fig)
        assert set(_zone_patches(fig)) == {"pond"}
    finally:
        plt.close(fig)
