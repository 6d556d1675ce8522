"""Each unit seen at its own class's height over terrain: live, in deliberation, in previews (issue 32).

The ground: flat to the west, where the threat stands (its eye 2 m up), a
crest 2 m high along x = 0, and east of it a plain ``drop`` metres lower.
Behind the crest a threat's lowest visible height is exactly the crest's
sight line: 2 m above the plain (``drop`` 0) or 7 m (``drop`` 5).  At 2 m a
soldier (1.8 m) is hidden (``v`` 0.34) where a wheeled vehicle (2.5 m) is
seen (``v`` 0.77); at 7 m the soldier is hidden past the cull's bound, the
vehicle not.  The planner's class is ``foot``: its windows are swept at
1.8 m, and a wheeled unit's field is the same windows at 2.5 m.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pfp_service.core import PlannerParams, ThreatField, kernels
from pfp_service.core.cull import RELATIVE_BOUND
from pfp_service.core.visibility import AtHeight
from pfp_service.terrain.grid import TerrainGrid
from pfp_service.terrain.live import of_grid
from pfp_service.wire import DirectionStatus, Goal, GoalMobility, ReplanEvent, ThreatUpdate, UnitState
from pfp_service.world.preview import preview
from pfp_service.world.terrain import sight_of
from pfp_service.world.world import GoalSet, StateReported, ThreatPut, World, WorldSettings

pytestmark = pytest.mark.unit

THREAT = ThreatUpdate(position=(-1000.0, 0.0), facing_deg=90.0, sigma_range=800.0, sigma_lateral=800.0)
EAST = (500.0, -300.0)  # behind the crest
START, GOAL = (300.0, -800.0), Goal(position=(300.0, 800.0))  # across the threat's front, behind the crest


def _ground(drop_m: float) -> TerrainGrid:
    xs = np.linspace(-3000.0, 3000.0, 601)  # 10 m cells
    gx, _ = np.meshgrid(xs, xs)
    crest = np.clip(2.0 - 0.1 * (np.abs(gx) - 20.0), 0.0, 2.0)  # 2 m, 40 m wide on top, 6 degree flanks
    plain = -drop_m * np.clip((gx - 40.0) / 40.0, 0.0, 1.0)  # east of it, ``drop_m`` lower (7 degrees)
    return TerrainGrid(-3000.0, -3000.0, xs[1] - xs[0], np.where(gx > 40.0, plain, crest))


class Counted:
    """A ground that counts its sweeps."""

    def __init__(self, ground) -> None:
        self.ground, self.calls = ground, 0
        self.zones, self.resolution_m, self.unit = ground.zones, ground.resolution_m, ground.unit

    def barriers(self, max_slope_deg):
        return self.ground.barriers(max_slope_deg)

    def sees(self, a, b, clearance_m: float = 0.0) -> bool:
        return self.ground.sees(a, b, clearance_m)

    def __call__(self, threat, box):
        self.calls += 1
        return self.ground(threat, box)


def _world(ground) -> World:
    return World(WorldSettings(planner=PlannerParams(), deliberation="inline", terrain=ground, lookahead=0))


def _state(xy, kind: str | None, seq: int = 1) -> UnitState:
    return UnitState(position=xy, seq=seq, mobility=None if kind is None else GoalMobility(kind=kind))


def _one(out, uid):
    (d,) = [d for d in out.directions if d.unit == uid]
    return d


def _level(w: World, uid: str, xy) -> float:
    rec = w.records.units[uid]
    return float(w.records.field_for(*w._route(rec)).level(np.array([xy]))[0])


def _blind(w: World) -> float:
    """The threats' level at ``EAST`` as if they saw through the ground."""
    return float(ThreatField(w.field.threats).level(np.array([EAST]))[0])


def test_behind_a_crest_between_two_heights_the_soldier_is_hidden_where_the_vehicle_is_seen():
    ground = Counted(of_grid(_ground(0.0), "foot"))
    w = _world(ground)
    w.apply([ThreatPut("t", THREAT)], 0.0)
    units = {"short": "foot", "tall": "wheeled", "planner": None}
    for uid, kind in units.items():
        w.apply([StateReported(uid, _state(START, kind))], 0.0)
    out = w.apply([GoalSet(uid, GOAL) for uid in units], 0.0)
    t = _blind(w)
    v = {uid: _level(w, uid, EAST) / t for uid in units}
    # L = 2 m behind the crest (to the window's coarsening): v = sigmoid((height - 2) / (height / 6))
    assert v["short"] == pytest.approx(1.0 / (1.0 + math.exp(-(1.8 - 2.0) / 0.3)), abs=0.05), v
    assert v["tall"] == pytest.approx(1.0 / (1.0 + math.exp(-(2.5 - 2.0) / (2.5 / 6.0))), abs=0.05), v
    assert v["short"] < 0.5 <= v["tall"] and v["planner"] == v["short"]
    assert ground.calls == 1  # one sweep, at the planner's class's height, for every unit
    assert out.directions[0].threat_level > 0.0


@pytest.mark.parametrize("planner", ["foot", "wheeled"])
def test_a_units_live_direction_is_the_one_a_planner_of_its_own_class_gives(planner):
    """One unit ("u": its escapes' seed is its own), as a soldier and as a vehicle, under a planner of either
    class: its direction depends on its own class, never on the planner's."""

    def told(kind: str | None, planner: str):
        w = _world(of_grid(_ground(0.0), planner))
        w.apply([ThreatPut("t", THREAT), StateReported("u", _state(START, kind))], 0.0)
        return _one(w.apply([GoalSet("u", GOAL)], 0.0), "u")

    other = "foot" if planner == "wheeled" else "wheeled"
    short, tall = told("foot", planner), told("wheeled", planner)
    assert short.vector == pytest.approx(told(None, "foot").vector, abs=1e-12)
    assert tall.vector == pytest.approx(told(None, "wheeled").vector, abs=1e-12)
    assert told(None, other).vector == pytest.approx(told(other, planner).vector, abs=1e-12)
    # the vehicle, seen behind the crest where the soldier is not, is routed further from the threat (east)
    assert tall.vector[0] > short.vector[0] + 0.05, (tall.vector, short.vector)
    assert tall.threat_level > 2.0 * short.threat_level


def test_units_of_one_height_share_one_field_and_no_window_is_swept_again():
    ground = Counted(of_grid(_ground(0.0), "foot"))
    w = _world(ground)
    w.apply([ThreatPut("t", THREAT)], 0.0)
    for uid, kind, x in (("a", "wheeled", 400.0), ("b", "wheeled", 600.0), ("c", "tracked", 700.0)):
        w.apply([StateReported(uid, _state((x, -300.0), kind)), GoalSet(uid, Goal(position=(x, 300.0)))], 0.0)
    fields = {uid: w.records.field_for(*w._route(w.records.units[uid])) for uid in "abc"}
    assert fields["a"] is fields["b"] is fields["c"]  # a tracked vehicle stands 2.5 m too
    assert len(w.records._tall[1]) == 1 and ground.calls == 1
    base, tall = w.field.packed, fields["a"].packed
    assert np.array_equal(base[:, kernels.VIS_DATA :], tall[:, kernels.VIS_DATA :])  # the same heights
    assert base[0, kernels.VIS_HEIGHT] == 1.8 and tall[0, kernels.VIS_HEIGHT] == 2.5
    # a window at another height is the same array under another target height
    window = ground.ground(w.field.threats[0], (-4000.0, -4000.0, 4000.0, 4000.0))
    assert window.at(2.5).low_m is window.low_m and window.at(1.8) is window
    # the sight a worker keys its fields by is equal for equal heights (one field per height there too)
    assert sight_of(ground, 2.5) == AtHeight(ground, 2.5) and hash(sight_of(ground, 2.5)) == hash(
        AtHeight(ground, 2.5)
    )
    assert sight_of(ground, None) is ground


def test_a_threat_put_re_directs_the_vehicle_it_sees_and_not_the_soldier_it_cannot():
    w = _world(of_grid(_ground(5.0), "foot"))  # behind the crest L = 7 m: past the cull's bound for 1.8 m
    for uid, kind, x in (("short", "foot", 500.0), ("tall", "wheeled", 520.0)):
        w.apply([StateReported(uid, _state((x, -300.0), kind)), GoalSet(uid, Goal(position=(x, 300.0)))], 0.0)
    out = w.apply([ThreatPut("t", THREAT)], 1.0)
    (replan,) = [e for e in out.events if isinstance(e, ReplanEvent)]
    assert replan.units == ["tall"], replan
    t = _blind(w)
    assert _level(w, "short", EAST) < RELATIVE_BOUND * t < _level(w, "tall", EAST)


def _walk_live(w, uid, pos, step, steps, t0):
    track = [pos]
    for k in range(1, steps + 1):
        d = _one(w.apply([StateReported(uid, _state(pos, None, k))], t0 + k), uid)
        if d.status not in (DirectionStatus.EN_ROUTE, DirectionStatus.ESCAPING):
            return track, d
        s = min(step, d.distance_to_goal) if d.distance_to_goal is not None else step
        pos = (pos[0] + s * d.vector[0], pos[1] + s * d.vector[1])
        track.append(pos)
    return track, d


def test_a_preview_of_a_vehicle_replays_its_live_track_at_its_own_height():
    w = _world(of_grid(_ground(0.0), "foot"))
    start, goal = (300.0, -1200.0), Goal(position=(300.0, 1200.0))
    w.apply([ThreatPut("t", THREAT), StateReported("tall", _state(start, "wheeled"))], 0.0)
    w.apply([GoalSet("tall", goal)], 0.0)
    view = w.view("tall")
    assert view.height_m == 2.5
    pv = preview(view, None, lambda: 0.0, 60.0, 100_000)
    wrong = preview(dataclasses.replace(view, height_m=None), None, lambda: 0.0, 60.0, 100_000)
    live, last = _walk_live(w, "tall", start, view.stepper.params.step, 100_000, 1.0)
    assert pv.status.value == "reached" and last.status is DirectionStatus.ARRIVED
    assert len(pv.path) == len(live), (len(pv.path), len(live))
    err = np.max(np.hypot(*(np.array(pv.path) - np.array(live)).T))
    assert err <= 1e-6 * pv.length, err
    # seen at the planner's 1.8 m instead, the same unit would have gone another way
    n = min(len(wrong.path), len(pv.path))
    gap = np.max(np.hypot(*(np.array(wrong.path[:n]) - np.array(pv.path[:n])).T))
    assert gap > 1.0, gap


def test_a_preview_worker_builds_the_vehicles_field_at_its_height(monkeypatch):
    """What a preview worker runs (``node.preview_work.compute``): its shared field keyed by the unit's sight."""
    import json

    from pfp_service.node import preview_work, workerproc
    from pfp_service.wire import PreviewRequest

    w = _world(of_grid(_ground(0.0), "foot"))
    w.apply([ThreatPut("t", THREAT), StateReported("tall", _state(START, "wheeled"))], 0.0)
    w.apply([GoalSet("tall", GOAL)], 0.0)
    view = w.view("tall")
    monkeypatch.setitem(workerproc._WORLD, "threats", view.threats)
    monkeypatch.setitem(workerproc._WORLD, "fields", {})
    kind, body = preview_work.compute((view, PreviewRequest(), None, 60.0, 100_000))
    assert kind == "reply", body
    got = json.loads(body)["path"]
    pv = preview(w.view("tall"), None, lambda: 0.0, 60.0, 100_000)
    assert np.max(np.abs(np.array(got) - np.array(pv.path))) <= 1e-9
    (key,) = workerproc._WORLD["fields"]
    assert key[1] == AtHeight(w.settings.terrain, 2.5)
