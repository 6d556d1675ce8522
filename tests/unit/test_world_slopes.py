"""A unit's own slope limit over terrain: its barrier set built off the loop, then planned at (issue 32).

The ground is ``test_world_mobility``'s mesa, whose walls climb 22 degrees.  A
wheeled unit told it climbs 25 is planned at wheels' 17 (the safe side) until
the set for 25 lands, and then guided up the wall.
"""

from __future__ import annotations

import pytest

from pfp_service.core import PlannerParams
from pfp_service.terrain import barriers as terrain_barriers
from pfp_service.terrain.live import of_grid
from pfp_service.wire import Goal, GoalMobility, ReplanEvent, UnitState
from pfp_service.world.slopes import SLOPE_RETRY_S, SLOPE_SETS, SLOPE_WAIT_S
from pfp_service.world.terrain import SlopeLanded, answer_slope
from pfp_service.world.world import GoalSet, StateReported, World, WorldSettings
from tests.unit.test_world_mobility import ON_THE_WALL, _mesa

pytestmark = pytest.mark.unit


@pytest.fixture(scope="module")
def ground():
    g = of_grid(_mesa(), "foot")
    g.hold_class_limits()  # as the planner does before it serves: a test run first would build them in apply
    return g


@pytest.fixture(scope="module")
def built(ground):
    """The sets of every limit these tests land, built once (as the node's thread would)."""
    return {lim: ground.build_barriers(lim) for lim in range(18, 18 + SLOPE_SETS + 2)}


def _world(ground) -> World:
    return World(WorldSettings(planner=PlannerParams(), deliberation="inline", terrain=ground, lookahead=0))


def _wheeled(slope: float | None, x: float = 0.0, seq: int = 1) -> UnitState:
    return UnitState(
        position=(x, -2000.0), seq=seq, mobility=GoalMobility(kind="wheeled", max_slope_deg=slope)
    )


def _status(out, uid: str) -> tuple[str, str]:
    (d,) = [d for d in out.directions if d.unit == uid]
    return d.status.value, d.reason or ""


def _landed(built, ask) -> SlopeLanded:
    return SlopeLanded(ask.limit, ask.serial, built[ask.limit])


def _send(w: World, units: dict[str, float], now: float = 0.0):
    w.apply([StateReported(u, _wheeled(s, 40.0 * k)) for k, (u, s) in enumerate(units.items())], now)
    return w.apply([GoalSet(u, Goal(position=ON_THE_WALL)) for u in units], now)


def test_an_override_plans_at_the_class_until_its_set_lands_then_up_a_slope_the_class_refuses(ground, built):
    w = _world(ground)
    out = _send(w, {"u": 25.0})
    status, reason = _status(out, "u")
    assert status == "trapped" and "slope>17deg" in reason  # the safe side: wheels' 17 on a 22-degree wall
    assert any(z.startswith("slope>17deg") for z in w.view("u").zones.ids)  # its preview plans as it does
    (ask,) = out.slopes
    assert ask.limit == 25
    stepper = w.records.units["u"].stepper
    assert stepper is not None
    version = stepper.version
    out = w.apply([StateReported("u", _wheeled(25.0, seq=2))], 1.0)
    assert not out.slopes  # asked once
    out = w.apply([_landed(built, ask)], 2.0)  # the set lands: re-judged at once, and directed
    assert stepper.version == version + 1
    assert _status(out, "u")[0] == "en_route"
    (ev,) = [e for e in out.events if isinstance(e, ReplanEvent)]
    assert ev.units == ["u"] and "25deg built" in ev.reason
    ids = w.view("u").zones.ids
    assert not any(z.startswith("slope>17deg") for z in ids)
    assert all(not z.startswith("slope>") or z.startswith("slope>25deg") for z in ids)
    # a unit that climbs 20 is on the safe side still (its own set not landed): two limits, two fields
    out = _send(w, {"v": 20.0}, 3.0)
    assert _status(out, "v")[0] == "trapped" and [a.limit for a in out.slopes] == [20]


def test_the_loop_never_builds_a_set(ground, built, monkeypatch):
    calls: list[float] = []
    real = terrain_barriers.barrier_zones
    monkeypatch.setattr(terrain_barriers, "barrier_zones", lambda g, deg: calls.append(deg) or real(g, deg))
    w = _world(ground)
    out = _send(w, {"a": 25.0, "b": 19.0})
    w.view("a"), w.view("b")
    out2 = w.apply([StateReported("a", _wheeled(25.0, seq=2))], 1.0)
    assert calls == []  # neither apply nor a view built one: asked instead
    asks = {a.limit: a for a in [*out.slopes, *out2.slopes]}
    assert set(asks) == {19, 25}
    landed = answer_slope(ground, asks[25])  # what the node's thread does
    assert calls == [25.0] and landed.zones is not None
    out = w.apply([landed], 2.0)
    assert calls == [25.0] and _status(out, "a")[0] == "en_route"


def test_a_limit_beyond_the_cap_plans_at_the_class_and_an_event_says_so(ground, built):
    w = _world(ground)
    units = {f"u{lim}": float(lim) for lim in range(18, 18 + SLOPE_SETS)}
    out = _send(w, units)
    asks = sorted(out.slopes, key=lambda a: a.limit)
    assert len(asks) == SLOPE_SETS
    out = _send(w, {"late": 18.0 + SLOPE_SETS}, 1.0)  # a ninth distinct limit, while eight are wanted
    assert not out.slopes
    (ev,) = [e for e in out.events if isinstance(e, ReplanEvent) and "beyond" in e.reason]
    assert ev.units == ["late"] and f"{SLOPE_SETS} override slope sets" in ev.reason and "17deg" in ev.reason
    out = w.apply([_landed(built, a) for a in asks], 2.0)
    told = {u for e in out.events if isinstance(e, ReplanEvent) and "built" in e.reason for u in e.units}
    assert told == set(units)  # each re-judged at its own limit: over the 22-degree wall from 23 up
    assert {u for u in units if _status(out, u)[0] == "en_route"} == {"u23", "u24", "u25"}
    late = w.apply([StateReported("late", _wheeled(18.0 + SLOPE_SETS, 80.0, seq=2))], 3.0)
    assert _status(late, "late")[0] == "trapped" and not late.slopes  # not asked again before the retry
    assert w.records.slopes.counts() == {"held": SLOPE_SETS, "asked": 0, "failed": 1}


def test_the_least_recently_used_set_no_unit_wants_is_evicted(ground, built):
    w = _world(ground)
    units = {f"u{lim}": float(lim) for lim in range(18, 18 + SLOPE_SETS)}
    out = _send(w, units)
    w.apply([_landed(built, a) for a in out.slopes], 1.0)
    assert list(w.records.slopes.held) != []
    # two units drop their own limit: 18 and 19 are wanted no more; 19's set was planned at after 18's
    w.apply([StateReported("u19", _wheeled(None, 40.0, seq=2))], 2.0)
    w.apply([StateReported("u18", _wheeled(None, 0.0, seq=2))], 3.0)
    w.view("u18"), w.view("u19")
    out = _send(w, {"new": 18.0 + SLOPE_SETS}, 4.0)
    assert [a.limit for a in out.slopes] == [18 + SLOPE_SETS]
    held = set(w.records.slopes.held)
    assert 18 not in held and 19 in held and len(held) == SLOPE_SETS - 1  # the LRU one no unit wants
    assert not any(k[0] == 18 for k in w.records._sets[1])  # its zone sets dropped with it
    out = w.apply([_landed(built, out.slopes[0])], 5.0)
    assert _status(out, "new")[0] == "en_route" and len(w.records.slopes.held) == SLOPE_SETS


def test_a_failed_or_late_set_leaves_the_unit_at_the_class_limit_and_says_why(ground, built):
    w = _world(ground)
    out = _send(w, {"u": 25.0})
    (ask,) = out.slopes
    out = w.apply([SlopeLanded(ask.limit, ask.serial, None, "MemoryError: boom")], 1.0)
    assert not out.directions  # nothing changed for it: not re-judged
    (ev,) = [e for e in out.events if isinstance(e, ReplanEvent)]
    assert (
        ev.units == ["u"] and "not built (MemoryError: boom)" in ev.reason and "planned at 17deg" in ev.reason
    )
    out = w.apply([StateReported("u", _wheeled(25.0, seq=2))], 2.0)
    assert (
        _status(out, "u")[0] == "trapped" and not out.slopes
    )  # failed: asked again no sooner than the retry
    out = w.apply([StateReported("u", _wheeled(25.0, seq=3))], 1.0 + SLOPE_RETRY_S + 1.0)
    assert not out.slopes  # the world notes the time at the end of an apply: asked at the next one
    out = w.apply([StateReported("u", _wheeled(25.0, seq=4))], 1.0 + SLOPE_RETRY_S + 2.0)
    (again,) = out.slopes
    assert again.serial != ask.serial
    t = 1.0 + SLOPE_RETRY_S + 2.0 + SLOPE_WAIT_S
    out = w.apply([StateReported("u", _wheeled(25.0, seq=5))], t)  # not landed in time: given up
    assert any("not built within" in e.reason for e in out.events if isinstance(e, ReplanEvent))
    out = w.apply([_landed(built, again)], t + 1.0)  # a late landing is dropped
    assert not out.directions and not w.records.slopes.held
    stale = w.apply([_landed(built, ask)], t + 2.0)  # and one for an older ask
    assert not w.records.slopes.held and not stale.events


def test_a_class_limit_override_asks_for_nothing_and_below_every_class_is_refused(ground):
    from pfp_service.world.mobility import refusal

    w = _world(ground)
    out = _send(w, {"a": 30.4, "b": 31.0, "c": 17.2})
    assert not out.slopes
    refused = refusal(Goal(position=ON_THE_WALL, mobility=GoalMobility(kind="foot", max_slope_deg=16.0)))
    assert refused is not None and refused.path == "$.mobility.max_slope_deg"


def test_the_nodes_builder_lands_a_set_and_a_failure_as_values_off_the_calling_thread(ground):
    """A terrain made from a grid (no name to pass a worker) is built on the builder's thread."""
    import queue
    import threading

    from pfp_service.node.terrain import Sights
    from pfp_service.world.terrain import SlopeAsk

    landed: queue.Queue = queue.Queue()
    s = Sights(ground, lambda x: landed.put((threading.get_ident(), x)))
    s.build([SlopeAsk(20, 1), SlopeAsk(20, 2)])  # latest wins per limit
    who, got = landed.get(timeout=60.0)
    assert who != threading.get_ident() and (got.limit, got.serial) == (20, 2) and got.zones
    assert got.zones == ground.build_barriers(20)

    class Broken:
        def build_barriers(self, max_slope_deg):
            raise MemoryError("no room")

    s = Sights(Broken(), lambda x: landed.put((threading.get_ident(), x)))  # type: ignore[arg-type]
    s.build([SlopeAsk(21, 3)])
    _, bad = landed.get(timeout=60.0)
    assert bad.zones is None and "MemoryError: no room" in bad.error  # a failure lands, as a value
    assert landed.empty()
