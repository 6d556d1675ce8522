"""Keep-out zones in the live world: put, moved, deleted, expired; re-direction, previews, durability, peers."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest

from pfp_service.core import PlannerParams
from pfp_service.node.store import Store
from pfp_service.wire import (
    Goal,
    RejectedEvent,
    ReplanEvent,
    UnitState,
    decode_event,
    decode_world_snapshot,
    encode,
)
from pfp_service.wire.messages import ZoneCircle, ZoneUpdate
from pfp_service.world.kinds import inputs_from_snapshot
from pfp_service.world.preview import preview
from pfp_service.world.world import (
    GoalSet,
    StateReported,
    Tick,
    World,
    WorldSettings,
    ZonePut,
    ZoneRemoved,
)

pytestmark = pytest.mark.unit

WALL = ZoneUpdate(polygon=[[(40.0, -30.0), (45.0, -30.0), (45.0, 30.0), (40.0, 30.0), (40.0, -30.0)]])


def _world(**kw) -> World:
    return World(WorldSettings(planner=PlannerParams(intensity="density"), **kw))


def _state(uid: str, x: float, y: float) -> StateReported:
    return StateReported(uid, UnitState(position=(x, y)))


def _events(out, kind):
    return [e for e in out.events if isinstance(e, kind)]


def _guided(w: World, units: dict[str, tuple[tuple[float, float], tuple[float, float]]]) -> None:
    w.apply([_state(u, *a) for u, (a, _b) in units.items()], 0.0)
    w.apply([GoalSet(u, Goal(position=b)) for u, (_a, b) in units.items()], 0.0)


def test_a_zone_put_redirects_the_units_whose_corridor_it_meets_with_one_replan_event():
    w = _world()
    _guided(w, {"a": ((0, 0), (100, 0)), "b": ((0, 10), (100, 10)), "far": ((0, 5000), (100, 5000))})
    out = w.apply([ZonePut("wall", WALL)], 1.0)
    assert {d.unit for d in out.directions} == {"a", "b"}
    (ev,) = _events(out, ReplanEvent)
    assert ev.units == ["a", "b"] and ev.reason == "zone wall put"
    decode_event(encode(ev))  # within the schema
    assert w.counts()["zones"] == 1 and w.field.zones.ids == ("wall",)
    moved = ZoneUpdate(circle=ZoneCircle(centre=(50.0, 5000.0), radius_m=10.0))
    out = w.apply([ZonePut("wall", moved)], 2.0)  # moved: the units it left and the one it reaches
    assert {d.unit for d in out.directions} == {"a", "b", "far"}
    out = w.apply([ZoneRemoved("wall")], 3.0)
    assert [d.unit for d in out.directions] == ["far"] and _events(out, ReplanEvent)[
        0
    ].reason == "zone wall removed"
    assert not w.field.zones and w.counts()["zones"] == 0
    assert not w.apply([ZoneRemoved("wall")], 4.0)  # never known (any more): nothing changes


def test_a_zone_expires_at_its_ttl_and_one_put_again_lives_on():
    w = _world()
    _guided(w, {"a": ((0, 0), (100, 0))})
    w.apply([ZonePut("z", msgspec.structs.replace(WALL, ttl_s=5.0))], 0.0)
    assert not w.apply([Tick(4.9)], 4.9)
    out = w.apply([Tick(5.0)], 5.0)
    assert _events(out, ReplanEvent)[0].reason == "zone z expired" and not w.field.zones
    w.apply([ZonePut("z", msgspec.structs.replace(WALL, ttl_s=5.0))], 6.0)
    w.apply([ZonePut("z", WALL)], 7.0)  # put again without a TTL: the old timer must not expire it
    w.apply([Tick(20.0)], 20.0)
    assert w.field.zones.ids == ("z",)


def test_zones_beyond_max_zones_are_refused_on_their_key():
    w = _world(max_zones=2)
    out = w.apply([ZonePut(f"z{i}", WALL) for i in range(3)], 0.0)
    (rej,) = _events(out, RejectedEvent)
    assert rej.key.endswith("/zone/z2") and "max_zones" in rej.reason
    assert w.counts()["zones"] == 2
    assert not _events(w.apply([ZonePut("z0", WALL)], 1.0), RejectedEvent)  # a zone held may move


def test_a_preview_respects_the_zones_in_force():
    w = _world()
    _guided(w, {"a": ((0, 0), (100, 0))})
    w.apply([ZonePut("wall", WALL)], 1.0)
    view = w.view("a")
    assert view.zones.ids == ("wall",)
    result = preview(view, None, lambda: 0.0, 30.0, 200_000)
    path = np.asarray(result.path)
    assert not view.zones.contains(path).any()
    assert result.status.value == "reached"


def test_the_snapshot_lists_the_zones_and_a_joining_planner_takes_them_with_the_time_left():
    w = _world()
    w.apply([ZonePut("a", WALL), ZonePut("b", msgspec.structs.replace(WALL, ttl_s=10.0))], 0.0)
    snap = decode_world_snapshot(encode(w.snapshot(4.0)))
    assert [z.id for z in snap.zones] == ["a", "b"] and snap.zones_total == 2
    assert snap.zones[0].ttl_s is None and snap.zones[1].ttl_s == pytest.approx(6.0)
    assert not w.snapshot(4.0, threats_from="x", zones_limit=0).zones  # left out when asked
    joined = World(WorldSettings(planner_id="p2"))
    joined.apply(inputs_from_snapshot(snap, "p2"), 100.0)
    assert joined.field.zones.ids == ("a", "b")
    joined.apply([Tick(105.9)], 105.9)
    assert joined.field.zones.ids == ("a", "b")
    joined.apply([Tick(106.1)], 106.1)
    assert joined.field.zones.ids == ("a",)


def test_zones_are_stored_and_restored_with_the_time_left(tmp_path):
    store = Store(tmp_path)
    short = msgspec.structs.replace(WALL, ttl_s=10.0)
    store.commit_inputs([ZonePut("a", WALL), ZonePut("b", short), ZonePut("c", short)], 1000.0, None)
    store.commit_inputs([ZoneRemoved("c")], 1001.0, None)
    store.close()
    store = Store(tmp_path)
    got = store.restore(1004.0)
    assert got.kept["zone"] == 2
    zones = {i.zone: i.update for i in got.inputs if isinstance(i, ZonePut)}
    assert set(zones) == {"a", "b"} and zones["a"] == WALL and zones["b"].ttl_s == pytest.approx(6.0)
    store.close()
    store = Store(tmp_path)
    later = store.restore(1011.0)  # b's time ran out while the planner was down
    assert [i.zone for i in later.inputs if isinstance(i, ZonePut)] == ["a"] and later.expired == 1
    store.close()


def test_the_log_says_each_zone_put_and_removed_in_one_line():
    import io
    import logging

    from pfp_service.node.log import get_logger, log_changes, setup_logging

    setup_logging("human", "info")
    out = io.StringIO()
    logging.getLogger("pfp").handlers[0].setStream(out)  # type: ignore[attr-defined]
    try:
        circle = ZoneUpdate(circle=ZoneCircle(centre=(5.0, 6.0), radius_m=12.5))
        log_changes(get_logger("test"), [ZonePut("wall", WALL), ZonePut("pond", circle), ZoneRemoved("old")])
    finally:
        logging.getLogger("pfp").handlers.clear()
    text = out.getvalue()
    assert "keep-out zone wall put: polygon of 4 corners from" in text
    assert "keep-out zone pond put: circle of 12.5 m at" in text
    assert "keep-out zone old removed" in text


def test_a_zone_change_keeps_the_threats_field_and_a_threat_change_keeps_the_zones():
    from pfp_service.wire import ThreatUpdate

    w = _world()
    threat = ThreatUpdate(position=(500.0, 500.0), facing_deg=0.0, sigma_range=5.0, sigma_lateral=3.0)
    w.apply(
        [StateReported("a", UnitState(position=(0.0, 0.0))), GoalSet("a", Goal(position=(100.0, 0.0)))], 0.0
    )
    from pfp_service.world.world import ThreatPut

    w.apply([ThreatPut("t", threat)], 0.0)
    before = w.field
    w.apply([ZonePut("wall", WALL)], 1.0)
    after = w.field
    assert (
        after is not before and after.threats is before.threats
    )  # the preview service's cached blob still holds
    assert after.packed is before.packed and after.zones.ids == ("wall",)
    w.apply([ThreatPut("t2", threat)], 2.0)
    assert w.field.zones.ids == ("wall",) and len(w.field) == 2


def test_a_zone_put_on_a_units_goal_traps_it_and_one_put_round_a_unit_leads_it_out_first():
    from pfp_service.wire import DirectionStatus, TrappedEvent

    w = _world()
    _guided(w, {"inside": ((42.0, 0.0), (100.0, 0.0)), "goal_in": ((0.0, 10.0), (43.0, 10.0))})
    out = w.apply([ZonePut("wall", WALL)], 1.0)
    said = {d.unit: d for d in out.directions}
    assert said["goal_in"].status is DirectionStatus.TRAPPED
    (trapped,) = _events(out, TrappedEvent)
    assert trapped.unit == "goal_in" and trapped.reason == "the goal lies in zone wall"
    assert said["inside"].status is DirectionStatus.ESCAPING and "leave zone wall" in said["inside"].reason
    assert said["inside"].vector == pytest.approx((-1.0, 0.0))  # the shortest way out: 2 m west
