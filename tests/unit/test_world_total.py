"""``World.apply`` is total: any sequence of any inputs, at any times, never raises, and all it sends is valid.

Hypothesis drives one world with random batches of every input kind: ±0,
subnormals, huge and tiny coordinates, goals on or next to their unit,
duplicate ids, out-of-order times, deliberation results that are late, stale or
for no job, missions restored and shared with absurd parameters.  Every
direction, event and mission that comes out must decode as its wire message
(the schemas in ``schemas/`` are generated from the same Structs), and the
counters must add up.

The default profile runs in a few seconds (``make test``); a longer search is

    .venv/bin/python -m pytest -p no:cacheprovider tests/unit/test_world_total.py --hypothesis-profile=long

(the profiles are in ``tests/hypothesis_profiles.py``).  What a search once found is
kept as ``@example``s below, so it is tried first on every run.
"""

from __future__ import annotations

import math

import msgspec
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from pfp_service.core import PlannerParams, Resolved
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import (
    Goal,
    Mission,
    MissionParams,
    ThreatUpdate,
    UnitKind,
    UnitState,
    decode_direction,
    decode_event,
    decode_mission,
    encode,
)
from pfp_service.wire.messages import TeamUpdate, ZoneCircle, ZoneUpdate
from pfp_service.world.events import mission_message
from pfp_service.world.world import (
    Deliberated,
    GoalCancelled,
    GoalSet,
    InputRejected,
    MissionRestored,
    MissionShared,
    PeerPlanner,
    StateReported,
    TeamPut,
    TeamRemoved,
    ThreatPut,
    ThreatRemoved,
    Tick,
    TokenChanged,
    World,
    WorldSettings,
    ZonePut,
    ZoneRemoved,
)
from tests.hypothesis_profiles import profiled

pytestmark = pytest.mark.unit

SUB = 5e-324  # the smallest subnormal
TINY = 2.2250738585072014e-308  # the smallest normal
EDGE = [0.0, -0.0, SUB, -SUB, TINY, 1e-300, -1e-300, 1e-3, 1.0, 1e9, -1e9, 999_999_999.9999999]

units = st.sampled_from(["u0", "u1", "u2", "bad", "x" * 64, "A_b-9"])
threat_ids = st.sampled_from(["t0", "t1", "t2"])
zone_ids = st.sampled_from(["z0", "z1", "z2"])
planners = st.sampled_from(["planner", "p1", "p2"])
coord = st.one_of(st.sampled_from(EDGE), st.floats(-20.0, 20.0), st.floats(-1e9, 1e9))
point = st.tuples(coord, coord)
# goal overrides within the wire's bounds (it refuses the rest); a peer's mission may carry absurd ones
length = st.one_of(st.none(), st.sampled_from([1e-3, 0.1, 1.0, 1e9]), st.floats(1e-3, 50.0))
delta = st.one_of(st.none(), st.sampled_from([1e-9, 0.08, 1e9]), st.floats(1e-9, 1e3))
positive = st.one_of(st.sampled_from([SUB, TINY, 1e-3, 1e9]), st.floats(1e-3, 1e3))


@st.composite
def goals(draw: st.DrawFn) -> Goal:
    return Goal(position=draw(point), delta=draw(delta), tolerance=draw(length), step=draw(length))


@st.composite
def threats(draw: st.DrawFn) -> ThreatUpdate:
    sr = draw(st.one_of(st.sampled_from([1e-3, 1.0, 1e6]), st.floats(1e-3, 50.0)))
    sl = draw(st.one_of(st.sampled_from([1e-3, 1.0]), st.floats(1e-3, 50.0)))
    lo, hi = sorted((sr, sl))
    if hi > 1e6 * lo:
        sl = sr
    return ThreatUpdate(
        position=draw(point),
        facing_deg=draw(st.floats(-360.0, 360.0)),
        sigma_range=sr,
        sigma_lateral=sl,
        skew=draw(st.one_of(st.just(0.0), st.floats(0.0, 1000.0))),
        weight=draw(st.one_of(st.sampled_from([0.0, SUB, 1e-300, 1.0, 1e6]), st.floats(0.0, 1e6))),
        ttl_s=draw(st.one_of(st.none(), st.sampled_from([SUB, 1e-3, 0.5]), st.floats(1e-3, 100.0))),
    )


@st.composite
def resolved(draw: st.DrawFn) -> Resolved:
    return Resolved(
        delta=draw(positive),
        step=draw(positive),
        max_iter=draw(st.integers(1, 10_000_000)),
        tolerance=draw(positive),
        intensity=draw(st.sampled_from(["peak", "density"])),
        escape=draw(st.sampled_from(["none", "auto", "delta", "global"])),
        trap_window=draw(st.integers(2, 50)),
        progress_window=draw(st.integers(2, 500)),
        seed=draw(st.integers(0, 2**63 - 1)),
    )


def _mission(r: Resolved, goal: Goal, origin: tuple[float, float]) -> Mission:
    params = MissionParams(**{k: getattr(r, k) for k in MissionParams.__struct_fields__})
    return Mission(goal=goal, origin=origin, params=params)


@st.composite
def zones(draw: st.DrawFn) -> ZoneUpdate:
    """A keep-out zone the wire accepts: a rectangle or a circle, tiny to huge, anywhere."""
    x = draw(st.one_of(st.sampled_from(EDGE), st.floats(-20.0, 20.0)))
    y = draw(st.one_of(st.sampled_from(EDGE), st.floats(-20.0, 20.0)))
    size = draw(st.one_of(st.sampled_from([1e-3, 1.0, 1e5]), st.floats(1e-3, 50.0)))
    ttl = draw(st.one_of(st.none(), st.sampled_from([SUB, 1e-3, 0.5]), st.floats(1e-3, 100.0)))
    if draw(st.booleans()):
        return ZoneUpdate(circle=ZoneCircle(centre=(x, y), radius_m=size), ttl_s=ttl)
    ring = [(x, y), (x + size, y), (x + size, y + size), (x, y + size), (x, y)]
    return ZoneUpdate(polygon=[ring], ttl_s=ttl)


@st.composite
def teams(draw: st.DrawFn) -> TeamUpdate:
    """A team of the units above, in any roles: clashes across teams are the world's to refuse."""
    ids = draw(st.lists(units, unique=True, min_size=0, max_size=4))
    lead, follow, ctl, robots = (ids + [None] * 4)[:4]
    far = st.one_of(st.sampled_from([1e-3, 1.0, 1e5]), st.floats(1e-3, 1e5))
    return TeamUpdate(
        lead=lead if follow else draw(st.one_of(st.none(), st.just(lead))),
        follow=[follow] if follow and lead else [],
        controller=ctl,
        robots=[robots] if robots and ctl else [],
        standoff_m=draw(far),
        corridor_m=draw(far),
        radio_range_m=draw(far),
    )


tokens = st.tuples(st.integers(-1, 5), st.integers(-1, 5))
inputs = st.one_of(
    st.builds(
        StateReported,
        units,
        st.builds(
            UnitState,
            position=point,
            seq=st.one_of(st.none(), st.integers(0, 2**53 - 1)),
            kind=st.one_of(st.none(), st.sampled_from(list(UnitKind))),
        ),
    ),
    st.builds(GoalSet, units, goals()),
    st.builds(GoalCancelled, units),
    st.builds(ThreatPut, threat_ids, threats()),
    st.builds(ThreatRemoved, threat_ids),
    st.builds(ZonePut, zone_ids, zones()),
    st.builds(ZoneRemoved, zone_ids),
    st.builds(TeamPut, st.sampled_from(["a", "b"]), teams()),
    st.builds(TeamRemoved, st.sampled_from(["a", "b"])),
    st.builds(TokenChanged, units, st.booleans()),
    st.builds(
        InputRejected, st.sampled_from(["mumt/m/unit/u0/goal", "junk", ""]), st.just(InputError("$", "x"))
    ),
    st.builds(Deliberated, units, tokens, st.none()),
    st.builds(MissionRestored, units, goals(), point, resolved()),
    st.builds(MissionShared, units, st.builds(_mission, resolved(), goals(), point)),
    st.builds(PeerPlanner, planners, st.booleans()),
    st.builds(Tick, st.floats(0.0, 1e4)),
)
batches = st.lists(st.tuples(st.lists(inputs, max_size=8), st.floats(0.0, 1e4)), min_size=1, max_size=10)
settings_st = st.builds(
    WorldSettings,
    planner=st.sampled_from(
        [PlannerParams(), PlannerParams(intensity="density", delta=0.08), PlannerParams(escape="none")]
    ),
    unit_stale_s=st.sampled_from([0.5, 10.0]),
    unit_forget_s=st.sampled_from([None, 1.0, 600.0]),
    liveliness_debounce_s=st.sampled_from([0.0, 2.0]),
    lookahead=st.sampled_from([0, 5]),
    bounds=st.sampled_from([None, ((-100.0, -100.0), (100.0, 100.0))]),
    # deferred, as the service runs: an inline escape search on a 1e9 m map is unbounded (see _run)
    deliberation=st.just("deferred"),
    deliberation_budget_s=st.just(0.05),
    max_units=st.sampled_from([3, 100_000]),
    max_threats=st.sampled_from([2, 10_000]),
    max_zones=st.sampled_from([1, 1_000]),
    cluster=st.booleans(),
    origin=st.sampled_from([None, Origin(lat=48.0, lon=11.0)]),
)


def _check(out, world: World) -> None:
    for d in out.directions:
        decode_direction(encode(d))
    for e in out.events:
        decode_event(encode(e))
    for m in out.missions:
        decode_mission(encode(mission_message(m, world.settings.planner_id)))
    for f in out.faults:
        assert f.error and f.where and "Traceback" not in f.detail
    c = world.counts()
    assert 0 <= c["units_stale"] <= c["units"] and c["deliberating"] >= 0


def _searchable(job) -> bool:
    """Whether a job's search is small enough to run here: the workers kill a search at its budget, a test cannot."""
    s = job.stepper
    return max(map(abs, (*s.goal, *s.origin))) <= 1e3 and len(job.field.threats) <= 3


def _run(settings: WorldSettings, script: list[tuple[list, float]], run_jobs: bool) -> World:
    w = World(settings)
    pending: list = []
    for batch, now in script:
        out = w.apply([*pending, *batch], now)  # late results first, as the node feeds them
        _check(out, w)
        # answered as a worker would: the result, or "past its deadline" for a search too big to run here
        pending = [job.run(now if run_jobs and _searchable(job) else math.inf) for job in out.jobs]
    return w


# What searches found, kept so every run tries them first.
@example(
    settings=WorldSettings(),
    script=[
        (
            [StateReported("bad", UnitState(position=(0.0, 0.0))), GoalSet("bad", Goal(position=(SUB, SUB)))],
            0.0,
        )
    ],
    run_jobs=False,
)
@example(
    settings=WorldSettings(),
    script=[
        (
            [
                StateReported("bad", UnitState(position=(0.0, 0.0))),
                MissionRestored(
                    "bad",
                    Goal(position=(10.0, 0.0)),
                    (0.0, 0.0),
                    Resolved(1.0, SUB, 1_000_000, SUB, "peak", "auto", 20, 200, 0),
                ),
            ],
            0.0,
        )
    ],
    run_jobs=True,
)
@example(  # the look-ahead walks off the ±1e9 map: it is cut at the edge, never sent out of bounds
    settings=WorldSettings(),
    script=[
        (
            [StateReported("u0", UnitState(position=(1e9, 0.0))), GoalSet("u0", Goal(position=(-1e9, 0.0)))],
            0.0,
        )
    ],
    run_jobs=False,
)
@example(  # a diagonal of the map is farther than the wire's ±1e9: the distance is given as 1e9
    settings=WorldSettings(),
    script=[
        (
            [StateReported("u0", UnitState(position=(-1e9, -1e9))), GoalSet("u0", Goal(position=(1e9, 1e9)))],
            0.0,
        )
    ],
    run_jobs=False,
)
@example(  # a peer's mission with a subnormal step, taken over when the peer goes
    settings=WorldSettings(cluster=True, liveliness_debounce_s=0.0),
    script=[
        ([PeerPlanner("p1", True)], 0.0),
        (
            [
                MissionShared(
                    "u0",
                    _mission(
                        Resolved(SUB, SUB, 10, SUB, "peak", "auto", 20, 200, 0),
                        Goal(position=(5.0, 5.0)),
                        (0.0, 0.0),
                    ),
                ),
                GoalSet("u0", Goal(position=(5.0, 5.0))),
                StateReported("u0", UnitState(position=(0.0, 0.0))),
            ],
            0.1,
        ),
        ([PeerPlanner("p1", False), Tick(1.0)], 1.0),
        ([StateReported("u0", UnitState(position=(0.0, 0.0))), Tick(2.0)], 2.0),
    ],
    run_jobs=True,
)
@example(  # steps of 4,000 km: the look-ahead's lat/lon left the globe's bounds (found by the long profile)
    settings=WorldSettings(origin=Origin(lat=48.0, lon=11.0)),
    script=[
        (
            [
                StateReported("u0", UnitState(position=(0.0, 0.0))),
                GoalSet("u0", Goal(position=(598593630.8650813, -4.507907952438738e-184), delta=215.65)),
            ],
            4023.5,
        )
    ],
    run_jobs=True,
)
@example(  # a restored mission whose tolerance covered its distance, with a step of 2.2e-308 m, then a report
    # from 1e9 m away: its look-ahead overflowed in Job.run (found by the long profile)
    settings=WorldSettings(deliberation="deferred"),
    script=[
        (
            [
                MissionRestored(
                    "bad",
                    Goal(position=(0.0, 5e-324), tolerance=1.1, step=4.68),
                    (-1e-300, 0.001),
                    Resolved(1e9, TINY, 7992, 162.3, "peak", "auto", 15, 107, 23072818288700728),
                )
            ],
            3379.5,
        ),
        ([StateReported("bad", UnitState(position=(999999999.0, 1.0)))], 3380.0),
        ([StateReported("bad", UnitState(position=(999999999.0, 1.0)))], 3380.1),
    ],
    run_jobs=True,
)
@profiled()
@given(settings=settings_st, script=batches, run_jobs=st.booleans())
def test_apply_never_raises_and_everything_it_sends_is_valid(settings, script, run_jobs):
    _run(settings, script, run_jobs)


@profiled(20)
@given(script=batches)
def test_the_counters_match_the_records(script):
    w = _run(WorldSettings(deliberation="deferred", unit_forget_s=1.0, unit_stale_s=0.5), script, False)
    snap = w.snapshot(1e9, limit=1000)
    assert len(snap.units) == w.counts()["units"] and len(snap.threats) == w.counts()["threats"]
    assert sum(u.stale for u in snap.units) == w.counts()["units_stale"]
    msgspec.json.decode(encode(snap))  # the world reply encodes
