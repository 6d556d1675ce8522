"""The map's sans-I/O parts: threat outlines, the model's deltas and snapshots, and the vendored Leaflet."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pfp_clients.map.geometry import CORE_FRACTION, ZONE_FRACTION, outline, peak_point
from pfp_clients.map.model import (
    MAX_REJECTED_GROUPS,
    MapModel,
    eta_s,
    merge_deltas,
)
from pfp_clients.map.samples import (
    AliveSeen,
    DirectionSeen,
    EventSeen,
    GoalSeen,
    StateSeen,
    StatusSeen,
    ThreatSeen,
    WorldSeen,
)
from pfp_clients.map.server import STATIC_DIR

from pfp_service.wire import (
    ArrivedEvent,
    Direction,
    DirectionStatus,
    ForgottenEvent,
    Goal,
    PlannerStatus,
    RejectedEvent,
    StaleEvent,
    ThreatSummary,
    ThreatUpdate,
    UnitState,
    UnitSummary,
    WorldSnapshot,
)
from pfp_service.world import translate
from tests.conftest import ROOT

pytestmark = pytest.mark.unit

M = "m1"


def ratio(update: ThreatUpdate, pts: np.ndarray) -> np.ndarray:
    """A threat's own level over its peak, straight from the core's field (weight-free)."""
    from pfp_service.core.threat import ThreatField

    threat = translate.threat(update, "t")
    field = ThreatField([threat], "density")
    return np.asarray(field.level(pts) / (threat.peak_density() * threat.weight))


# -- geometry -----------------------------------------------------------------------
def test_core_of_an_unskewed_threat_is_the_half_maximum_ellipse():
    u = ThreatUpdate(position=(3.0, -2.0), facing_deg=0.0, sigma_range=2.0, sigma_lateral=1.0)
    pts = np.array(outline(u, CORE_FRACTION, rays=4))  # east, north, west, south of the peak
    r = math.sqrt(2 * math.log(2))  # README: the core is 1.18 sigma along and across the facing
    assert pts == pytest.approx(
        np.array([[3 + r, -2], [3, -2 + 2 * r], [3 - r, -2], [3, -2 - 2 * r]]), abs=2e-3
    )


@settings(max_examples=40, deadline=None)
@given(
    facing=st.floats(0, 360),
    sr=st.floats(0.5, 20),
    aspect=st.floats(0.2, 5),
    skew=st.floats(0, 8),
    fraction=st.sampled_from([ZONE_FRACTION, CORE_FRACTION]),
)
def test_every_outline_vertex_is_at_its_fraction_of_the_peak(facing, sr, aspect, skew, fraction):
    u = ThreatUpdate(
        position=(10.0, 20.0), facing_deg=facing, sigma_range=sr, sigma_lateral=sr * aspect, skew=skew
    )
    pts = np.array(outline(u, fraction))
    # vertices are rounded to the millimetre: the level moves by its slope, ~(2 + skew) / sigma, times that
    assert ratio(u, pts) == pytest.approx(fraction, abs=1e-3 * (2 + skew) / min(sr, sr * aspect, 1.0))
    peak = np.array([peak_point(translate.threat(u, "t"))])
    assert ratio(u, peak)[0] == pytest.approx(1.0, abs=1e-9)


def test_the_zone_contains_the_core():
    u = ThreatUpdate(position=(0.0, 0.0), facing_deg=225.0, sigma_range=5.0, sigma_lateral=3.5, skew=2.0)
    core, zone = np.array(outline(u, CORE_FRACTION)), np.array(outline(u, ZONE_FRACTION))
    c = np.array(peak_point(translate.threat(u, "t")))
    assert np.all(np.hypot(*(zone - c).T) > np.hypot(*(core - c).T))


def test_outline_refuses_a_fraction_outside_0_1():
    u = ThreatUpdate(position=(0.0, 0.0), sigma_range=1.0, sigma_lateral=1.0)
    with pytest.raises(ValueError, match="fraction"):
        outline(u, 1.0)


# -- model ---------------------------------------------------------------------------
def state(x: float, y: float, **kw) -> UnitState:
    return UnitState(position=(x, y), **kw)


def test_a_unit_appears_with_its_state_then_its_direction():
    m = MapModel()
    m.apply([StateSeen("u1", state(1, 2, kind="manned", speed_mps=1.5, heading_deg=90))], now=100.0)
    d = m.take_delta(100.0)
    assert d is not None
    u = d["units"]["u1"]
    assert (u["position"], u["kind"], u["speed_mps"], u["heading_deg"]) == ((1.0, 2.0), "manned", 1.5, 90)
    assert u["status"] is None and u["track_add"] == [(1.0, 2.0)] and not u["stale"]
    assert m.take_delta(100.1) is None  # nothing new: nothing sent
    direction = Direction(
        unit="u1",
        status=DirectionStatus.ESCAPING,
        vector=(0, 1),
        heading_deg=0,
        lookahead=[(1, 3), (1, 4)],
        reason="r",
    )
    m.apply([DirectionSeen("u1", direction)], now=100.2)
    u = m.take_delta(100.2)["units"]["u1"]
    assert (u["status"], u["reason"], u["lookahead"], u["heading_deg"]) == (
        "escaping",
        "r",
        [(1, 3), (1, 4)],
        0,
    )
    assert u["track_add"] == []  # the track did not move


def test_the_track_is_sent_once_and_kept_bounded():
    m = MapModel(track_max=5)
    for i in range(8):
        m.apply([StateSeen("u1", state(i, 0))], now=float(i))
        if i % 2:
            assert [p[0] for p in m.take_delta(float(i))["units"]["u1"]["track_add"]] == [i - 1, i]
    snap = m.snapshot(8.0)["units"]["u1"]
    assert [p[0] for p in snap["track"]] == [3, 4, 5, 6, 7]
    assert "track_add" not in snap


def test_silence_makes_a_unit_stale_and_a_report_revives_it():
    m = MapModel(stale_s=10.0)
    m.apply([StateSeen("u1", state(0, 0))], now=0.0)
    m.take_delta(0.0)
    assert m.take_delta(9.9) is None
    assert m.take_delta(10.1)["units"]["u1"]["stale"] is True
    assert m.take_delta(20.0) is None  # said once
    m.apply([StateSeen("u1", state(1, 0))], now=21.0)
    assert m.take_delta(21.0)["units"]["u1"]["stale"] is False


def test_a_withdrawn_token_makes_a_unit_stale_after_the_debounce():
    m = MapModel(stale_s=100.0, debounce_s=2.0)
    m.apply([StateSeen("u1", state(0, 0)), AliveSeen("u1", True)], now=0.0)
    m.take_delta(0.0)
    m.apply([AliveSeen("u1", False)], now=1.0)
    assert m.take_delta(1.0)["units"]["u1"]["stale"] is False  # a router restart looks like this
    m.apply([AliveSeen("u1", True)], now=2.0)
    m.apply([AliveSeen("u1", False)], now=5.0)
    assert m.take_delta(6.5)["units"]["u1"]["stale"] is False
    assert m.take_delta(7.0)["units"]["u1"]["stale"] is True


def test_the_planners_stale_event_greys_a_unit_until_it_reports():
    m = MapModel(stale_s=100.0)
    m.apply([StateSeen("u1", state(0, 0))], now=0.0)
    m.apply([EventSeen(StaleEvent(unit="u1", position=(0, 0), reason="silent"))], now=1.0)
    d = m.take_delta(1.0)
    assert d["units"]["u1"]["stale"] is True and d["events"][0]["kind"] == "stale"
    m.apply([StateSeen("u1", state(0, 1))], now=2.0)
    assert m.take_delta(2.0)["units"]["u1"]["stale"] is False


def test_goals_are_shown_and_cancelled():
    m = MapModel()
    m.apply([GoalSeen("u1", Goal(position=(5, 6)))], now=0.0)
    assert m.take_delta(0.0)["units"]["u1"]["goal"] == (5, 6)
    m.apply([GoalSeen("u1", None)], now=1.0)
    assert m.take_delta(1.0)["units"]["u1"]["goal"] is None


def test_threats_put_move_delete_and_expire_by_their_ttl():
    m = MapModel()
    t = ThreatUpdate(position=(5, 5), facing_deg=90, sigma_range=2, sigma_lateral=1, skew=1, ttl_s=30)
    m.apply(
        [
            ThreatSeen("e1", t),
            ThreatSeen("e2", ThreatUpdate(position=(0, 0), sigma_range=1, sigma_lateral=1)),
        ],
        10.0,
    )
    d = m.take_delta(10.0)
    e1 = d["threats"]["e1"]
    assert e1["expires_at"] == 40.0 and d["threats"]["e2"]["expires_at"] is None
    assert len(e1["zone"]) == len(e1["core"]) == 48 and e1["update"]["facing_deg"] == 90
    m.apply([ThreatSeen("e2", None), ThreatSeen("nope", None)], now=11.0)
    assert m.take_delta(11.0) == {"type": "delta", "now": 11.0, "threats_removed": ["e2"]}
    assert m.take_delta(39.9) is None
    assert m.take_delta(40.0)["threats_removed"] == ["e1"]
    assert m.snapshot(41.0)["threats"] == {}


def test_a_weightless_threat_has_a_zone_but_no_core():
    m = MapModel()
    m.apply([ThreatSeen("w0", ThreatUpdate(position=(0, 0), sigma_range=1, sigma_lateral=1, weight=0))], 0.0)
    assert m.snapshot(0.0)["threats"]["w0"]["core"] == [] and m.snapshot(0.0)["threats"]["w0"]["zone"]


def test_rejections_are_aggregated_per_key_kind_field_and_reason():
    m = MapModel()
    bad = [
        RejectedEvent(
            key=f"mumt/m/unit/u{i}/state", field="$.position[1]", reason="expected a finite number", t=i
        )
        for i in range(50)
    ]
    m.apply([EventSeen(e) for e in bad], now=100.0)
    m.apply(
        [EventSeen(RejectedEvent(key="mumt/m/threat/x", field="$.sigma_range", reason="too small"))], 100.0
    )
    d = m.take_delta(100.0)
    assert "events" not in d  # a flood of rejections does not flood the feed
    groups = sorted(d["rejected"].values(), key=lambda g: g["key_kind"])
    assert [(g["key_kind"], g["count"]) for g in groups] == [("threat", 1), ("unit_state", 50)]
    assert groups[1]["last_key"] == "mumt/m/unit/u49/state" and groups[1]["last_t"] == 49
    m.apply([EventSeen(bad[0])], 101.0)
    (group,) = m.take_delta(101.0)["rejected"].values()
    assert group["count"] == 51


def test_rejection_groups_are_bounded_when_reasons_quote_values():
    m = MapModel()
    flood = [
        RejectedEvent(
            key="mumt/m/unit/u1/state", field="$.position", reason=f"[{i}, 0] lies outside the bounds"
        )
        for i in range(MAX_REJECTED_GROUPS + 50)
    ]
    m.apply([EventSeen(e) for e in flood], now=1.0)
    assert len(m.rejected) == MAX_REJECTED_GROUPS + 1
    assert m.rejected["unit_state|*|other reasons"]["count"] == 50


def test_events_feed_keeps_the_latest_and_forgotten_units_leave_the_map():
    m = MapModel(events_max=3)
    m.apply([StateSeen("u1", state(0, 0))], 0.0)
    m.apply([EventSeen(ArrivedEvent(unit="u1", position=(0, 0), t=float(i))) for i in range(5)], 1.0)
    d = m.take_delta(1.0)
    assert [e["t"] for e in d["events"]] == [2.0, 3.0, 4.0] and d["events"][0]["kind"] == "arrived"
    m.apply([EventSeen(ForgottenEvent(unit="u1", stale_s=60))], 2.0)
    d = m.take_delta(2.0)
    assert d["units_removed"] == ["u1"] and "u1" not in m.snapshot(2.0)["units"]


def test_planner_status_is_kept_per_planner():
    m = MapModel()
    st1 = PlannerStatus(planner="p1", mission=M, uptime_s=3.0, units=2, latency_p50_ms=0.3)
    m.apply([StatusSeen(st1)], 5.0)
    s = m.take_delta(5.0)["status"]["p1"]
    assert (s["units"], s["latency_p50_ms"], s["received_at"]) == (2, 0.3, 5.0)


def test_a_world_reply_fills_in_what_no_sample_has_said_yet():
    m = MapModel()
    m.apply([StateSeen("u1", state(9, 9, kind="manned"))], 100.0)  # seen live: newer than the reply
    world = WorldSnapshot(
        planner="p",
        mission=M,
        units=[
            UnitSummary(id="u1", kind="unmanned", position=(1, 1), status="en_route", last_seen_s=2.0),
            UnitSummary(
                id="u2", kind="unmanned", position=(3, 4), status="trapped", reason="r", last_seen_s=2.5
            ),
        ],
        threats=[
            ThreatSummary(
                id="e1", threat=ThreatUpdate(position=(1, 1), sigma_range=1, sigma_lateral=1), ttl_s=7
            )
        ],
    )
    m.apply([WorldSeen(world)], 100.0)
    snap = m.snapshot(100.0)
    assert snap["units"]["u1"]["position"] == (9, 9) and snap["units"]["u1"]["kind"] == "manned"
    assert snap["units"]["u1"]["status"] == "en_route"  # no direction seen yet: the planner's word
    u2 = snap["units"]["u2"]
    assert (u2["position"], u2["status"], u2["last_seen"], u2["reason"]) == ((3, 4), "trapped", 97.5, "r")
    assert snap["threats"]["e1"]["expires_at"] == 107.0


def test_deltas_merged_for_a_slow_page_say_what_the_sequence_says():
    """A page that skipped frames gets one delta; applying it equals applying each in turn."""
    m = MapModel()
    t = ThreatUpdate(position=(0, 0), sigma_range=1, sigma_lateral=1)
    steps = [
        [StateSeen("u1", state(0, 0)), ThreatSeen("a", t), ThreatSeen("b", t)],
        [
            StateSeen("u1", state(1, 0)),
            ThreatSeen("a", None),
            EventSeen(ArrivedEvent(unit="u1", position=(1, 0))),
        ],
        [
            StateSeen("u1", state(2, 0)),
            StateSeen("u2", state(5, 5)),
            ThreatSeen("a", t),
            ThreatSeen("b", None),
        ],
        [EventSeen(ForgottenEvent(unit="u2"))],
    ]
    merged = None
    for i, batch in enumerate(steps):
        m.apply(batch, now=float(i))
        merged = merge_deltas(merged, m.take_delta(float(i)))
    assert merged["now"] == 3.0
    assert [p[0] for p in merged["units"]["u1"]["track_add"]] == [0, 1, 2]  # track points add up
    assert merged["units"]["u1"]["position"] == (2, 0)  # the newest view wins
    assert "u2" not in merged["units"] and merged["units_removed"] == ["u2"]
    assert set(merged["threats"]) == {"a"} and merged["threats_removed"] == ["b"]  # never both
    assert [e["kind"] for e in merged["events"]] == ["arrived", "forgotten"]
    assert merge_deltas(None, {"type": "delta", "now": 1.0}) == {"type": "delta", "now": 1.0}


def test_eta_needs_a_positive_speed():
    assert eta_s(30.0, 1.5) == 20.0
    assert eta_s(30.0, None) is None and eta_s(30.0, 0.0) is None


# -- packaging -------------------------------------------------------------------------
def test_leaflet_is_vendored_pinned_with_its_licence_and_shipped_as_package_data():
    leaflet = STATIC_DIR / "vendor" / "leaflet"
    assert "Leaflet 1.9.4" in (leaflet / "leaflet.js").read_text()[:200]
    assert "BSD 2-Clause" in (leaflet / "LICENSE").read_text()
    assert "leaflet@1.9.4" in (leaflet / "VERSION").read_text()
    assert (leaflet / "leaflet.css").is_file() and (leaflet / "images" / "marker-icon.png").is_file()
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    patterns = data["pfp_clients.map"]
    shipped = {p.relative_to(STATIC_DIR.parent).as_posix() for p in STATIC_DIR.rglob("*") if p.is_file()}
    from fnmatch import fnmatch

    assert all(any(fnmatch(f, pat) for pat in patterns) for f in shipped), shipped
    page = (STATIC_DIR / "index.html").read_text() + (STATIC_DIR / "map.js").read_text()
    assert (
        "http://" not in page.replace("http://tiles", "") and "https://" not in page
    )  # no CDN: the field has no internet
