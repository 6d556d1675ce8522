"""Trap escape: horseshoe, cup, symmetric block and enclosure, judged against threat cores."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Scheduled, Threat, ThreatField, plan, resolve
from pfp_service.core.batch import advise_many
from pfp_service.core.cores import CORE_FRACTION, Cores
from pfp_service.core.stepper import Stepper, StepStatus

pytestmark = pytest.mark.unit

START, GOAL = (0.0, 0.0), (100.0, 100.0)


def _arc(cx, cy, r, first_deg, last_deg, n, sigma=4.0):
    out = []
    for k in range(n):
        b = math.radians(first_deg + (last_deg - first_deg) * k / (n - 1))
        out.append(
            Threat.from_facing(
                (cx + r * math.sin(b), cy + r * math.cos(b)), 225, sigma, sigma, 0.5, 1.0, f"h{k}"
            )
        )
    return out


def horseshoe():  # open towards the start, its back to the goal
    return _arc(60, 60, 12, -55, 145, 9)


def cup():  # three straight walls
    pts = [(70 + 5 * k * 0.7071 - 15 * 0.7071, 70 - 5 * k * 0.7071 + 15 * 0.7071) for k in range(7)]
    ax, ay = -0.7071, -0.7071  # side walls run back towards the start
    for end in (pts[0], pts[-1]):
        pts += [(end[0] + 5 * j * ax, end[1] + 5 * j * ay) for j in (1, 2, 3)]
    return [Threat.from_facing(p, 225, 4, 4, 0.3, 1.0, f"c{i}") for i, p in enumerate(pts)]


def block():  # one unskewed threat square on the start-goal line
    return [Threat.from_facing((50, 50), 225, 6, 6, 0.0, 1.0, "b")]


def ring(cx=20.0, cy=20.0):
    return [
        Threat.from_facing((cx + 14 * math.sin(a), cy + 14 * math.cos(a)), 0, 4, 4, 0.0, 1.0, f"r{k}")
        for k, a in enumerate(np.linspace(0, 2 * math.pi, 16, endpoint=False))
    ]


def _plan(threats, escape, start=START, goal=GOAL, **kw):
    return plan(
        start,
        goal,
        [Scheduled(t) for t in threats],
        PlannerParams(escape=escape, **kw),
        None,
        time.perf_counter,
    )


def _core_entry(threats, path):
    return Cores(ThreatField(threats)).first_hit(np.asarray(path))


def _straight_exposure(threats, start=START, goal=GOAL):
    t = np.linspace(0.0, 1.0, 4001)[:, None]
    pts = np.asarray(start) + t * (np.asarray(goal) - np.asarray(start))
    return float(np.trapezoid(ThreatField(threats).level(pts), dx=math.dist(start, goal) / 4000))


def test_core_is_the_half_maximum_region():
    t = Threat.from_facing((0, 0), 0, 2.0, 1.0, 0.0)
    r = math.sqrt(2 * math.log(2))  # Mahalanobis radius of the half maximum
    inside = Cores(ThreatField([t])).inside(
        np.array([[0, 2 * r * 0.99], [0, 2 * r * 1.01], [r * 0.99, 0], [r * 1.01, 0]])
    )
    assert CORE_FRACTION == 0.5
    assert inside.tolist() == [True, False, True, False]
    assert not Cores(ThreatField([Threat.from_facing((0, 0), 0, 2.0, 1.0, 0.0, weight=0.0)])).inside(
        np.zeros((1, 2))
    )[0]


@pytest.mark.parametrize("make", [horseshoe, cup], ids=["horseshoe", "cup"])
def test_trap_is_escaped_with_low_exposure(make):
    threats = make()
    plain = _plan(threats, "none")
    assert plain.status.value == "trapped"  # the scenario really is a trap
    r = _plan(threats, "auto")
    assert r.status.value == "reached" and r.final_distance <= r.params.tolerance
    assert r.traps >= 1 and r.escapes and r.escape_steps > 0
    assert not _core_entry(threats, r.path)
    # low exposure: it skirts the threats (peak under half the core level, weights are 1)
    # and collects far less than driving straight through them would
    assert r.peak_threat < 0.25
    assert r.exposure < 0.5 * _straight_exposure(threats)


def test_symmetric_block_auto_never_passes_through_a_core():
    threats = block()
    assert _plan(threats, "none").status.value == "trapped"
    delta = _plan(threats, "delta")  # raising delta alone would cross the core: refused, honestly
    assert delta.status.value == "trapped" and "delta" in delta.reason
    assert not _core_entry(threats, delta.path)
    r = _plan(threats, "auto")
    assert r.status.value == "reached"
    assert "delta" not in r.escapes
    assert not _core_entry(threats, r.path)


@pytest.mark.parametrize("mode", ["auto", "delta", "random", "waypoint", "contour", "global"])
def test_enclosure_is_trapped_honestly_in_bounded_time(mode):
    threats = ring()
    t0 = time.perf_counter()
    r = _plan(threats, mode, start=(20.0, 20.0))
    assert time.perf_counter() - t0 < 5.0
    assert r.status.value == "trapped"
    assert "no escape found" in r.reason
    assert not _core_entry(threats, r.path)


def test_enclosure_round_the_goal_is_never_reached():
    threats = ring(100.0, 100.0)
    r = _plan(threats, "auto")
    assert r.status.value != "reached"
    assert not _core_entry(threats, r.path)


def test_every_escape_is_seeded_and_reproducible():
    a = _plan(block(), "random", seed=7)
    b = _plan(block(), "random", seed=7)
    assert a.path == b.path and a.escapes == b.escapes


def test_status_reads_escaping_while_escaping_and_live_drift_is_tolerated():
    threats = horseshoe()
    field = ThreatField(threats)
    params = resolve(PlannerParams(escape="auto"), START, GOAL, threats)
    s = Stepper(START, GOAL, params)
    x, y = START
    seen = []
    rng = np.random.default_rng(1)
    for _ in range(params.max_iter):
        adv = s.advise(field, x, y)
        seen.append(adv.status)
        if adv.status.terminal:
            break
        # a live unit does not move exactly as told
        x += params.step * adv.dx + rng.normal(0, 0.05 * params.step)
        y += params.step * adv.dy + rng.normal(0, 0.05 * params.step)
    assert StepStatus.ESCAPING in seen
    assert seen[-1] is StepStatus.ARRIVED
    assert s.traps >= 1 and s.escape_steps == seen.count(StepStatus.ESCAPING)


def test_advise_many_matches_advise_through_an_escape():
    threats = block()
    field = ThreatField(threats)
    params = resolve(PlannerParams(escape="auto"), START, GOAL, threats)
    one, many = (
        Stepper(START, GOAL, params),
        [Stepper(START, GOAL, params), Stepper((5.0, 0.0), GOAL, params)],
    )
    pos = np.array([START, (5.0, 0.0)])
    x, y = START
    for _ in range(400):
        a = one.advise(field, x, y)
        b = advise_many(many, field, pos)[0]
        assert a == b
        if a.status.terminal:
            break
        x, y = x + params.step * a.dx, y + params.step * a.dy
        pos[0] = (x, y)
        pos[1] += 0.0
    assert one.escapes


def test_plain_descent_is_untouched_by_escape_machinery():
    threats = horseshoe()[:3]
    a, b = _plan(threats, "none"), _plan(threats, "auto")
    if a.status.value == "reached":
        assert a.path == b.path and b.traps == 0 and b.escapes == []


def test_one_registry_gives_the_choices_the_order_and_the_tiers():
    import typing

    from pfp_service.core.escape import AUTO_ORDER
    from pfp_service.core.escape_strategies import STRATEGIES
    from pfp_service.core.params import ESCAPES, Escape

    assert ("none", "auto", *STRATEGIES) == ESCAPES
    assert typing.get_args(Escape) == ESCAPES
    assert tuple(STRATEGIES) == AUTO_ORDER
    tiers = [STRATEGIES[n].tier for n in AUTO_ORDER]
    assert tiers == sorted(tiers) and len(set(tiers)) >= 2
    assert all(s.name == n and s.summary for n, s in STRATEGIES.items())


def test_the_light_list_of_escape_names_is_the_registry_name_for_name():
    # options holds the names so the CLI and the validators need not compile the core; the registry
    # implements them, in auto's order; core.escape refuses to import when the two drift apart
    from pfp_service.core import options
    from pfp_service.core.escape_strategies import STRATEGIES

    assert tuple(STRATEGIES) == options.ESCAPE_STRATEGIES
    assert ("none", "auto", *STRATEGIES) == options.ESCAPES


def test_a_strategy_without_a_way_out_says_why_as_a_value():
    from pfp_service.core.escape_strategies import STRATEGIES, NoCandidate, Trap

    threats = ring()
    field = ThreatField(threats)
    p = resolve(PlannerParams(escape="contour"), (20.0, 20.0), GOAL, threats)
    tr = Trap(
        field, Cores(field), 20.0, 20.0, GOAL, p.delta, 0.0, p.step, p.tolerance, p.trap_window,
        math.dist((20.0, 20.0), GOAL), 4 * p.step, 2000, None, np.random.default_rng(0),
    )  # fmt: skip
    out = list(STRATEGIES["contour"].propose(tr))  # the ring's centre is flat: no slope
    assert isinstance(out[-1], NoCandidate) and "slope" in out[-1].reason
    assert isinstance(list(STRATEGIES["global"].propose(tr))[-1], NoCandidate)
    r = _plan(threats, "contour", start=(20.0, 20.0))
    assert r.status.value == "trapped" and "contour: " in r.reason


def test_one_lambda_ranks_every_path():
    import pfp_service.core.escape_strategies as strategies
    import pfp_service.core.optimal as optimal
    from pfp_service.core.metrics import LAMBDA, path_cost

    assert optimal.plan_optimal.__defaults__ is not None and LAMBDA in optimal.plan_optimal.__defaults__
    for mod in (strategies, optimal):
        assert all(v is LAMBDA for k, v in vars(mod).items() if k.endswith("LAMBDA"))
    path = np.array([[0.0, 0.0], [30.0, 40.0]])
    field = ThreatField(block())
    assert math.isclose(path_cost(path, ThreatField()), 50.0)
    e = path_cost(path, field, 1.0) - 50.0
    assert e > 0 and math.isclose(path_cost(path, field), 50.0 + LAMBDA * e)


def _gap_wall(ratio, sigma=4.0, half_len=90.0):
    """A wall across (0, 0) -> (100, 0) at x = 50 with one gap whose middle is ``ratio`` of the neighbours' peak."""
    g = sigma * math.sqrt(-2.0 * math.log(ratio))
    ys = [g + k * 1.2 * sigma for k in range(int((half_len - g) / (1.2 * sigma)) + 1)]
    return [
        Threat.from_facing((50.0, s * y), 270, sigma, sigma, 0.0, 1.0, f"w{i}")
        for i, y in enumerate(ys)
        for s in (1, -1)
    ]


def test_a_gap_open_by_the_core_rule_is_passed_when_cheaper():
    threats = _gap_wall(0.4)
    cores = Cores(ThreatField(threats))
    assert not cores.inside(np.array([[50.0, 0.0]]))[0]  # open by the rule: 0.4 of peak at its middle
    r = _plan(threats, "auto", goal=(100.0, 0.0))
    assert r.status.value == "reached" and not _core_entry(threats, r.path)
    assert max(abs(y) for _, y in r.path) < 20.0  # through the gap, not round a 90 m wall


def test_a_gap_shut_by_the_core_rule_is_gone_round():
    threats = _gap_wall(0.6)
    assert Cores(ThreatField(threats)).inside(np.array([[50.0, 0.0]]))[0]
    r = _plan(threats, "auto", goal=(100.0, 0.0))
    assert r.status.value == "reached" and not _core_entry(threats, r.path)
    assert max(abs(y) for _, y in r.path) > 80.0


def test_search_margin_is_explicit_and_inside_the_rule():
    from pfp_service.core.cores import SEARCH_FRACTION

    assert 0.45 < SEARCH_FRACTION < CORE_FRACTION  # routes keep a sliver of clearance from every core
    t = Threat.from_facing((0, 0), 0, 2.0, 2.0, 0.0)
    r_check, r_search = (math.sqrt(-2 * math.log(f)) for f in (CORE_FRACTION, SEARCH_FRACTION))
    pts = np.array([[2.0 * 0.5 * (r_check + r_search), 0.0]])
    assert (
        not Cores(ThreatField([t])).inside(pts)[0] and Cores(ThreatField([t]), SEARCH_FRACTION).inside(pts)[0]
    )


def test_a_goal_inside_a_core_is_named_in_the_reason():
    threats = [Threat.from_facing((95.0, 0.0), 270, 5.0, 5.0, 0.0, 1.0, "guard")]
    r = _plan(threats, "auto", goal=(100.0, 0.0))
    assert r.status.value == "trapped"
    assert "the goal lies in the core of threat guard" in r.reason


def test_a_start_inside_a_core_leaves_it_first_and_says_so():
    threats = [Threat.from_facing((2.0, 0.0), 0, 5.0, 5.0, 0.0, 1.0, "here")]
    cores = Cores(ThreatField(threats))
    assert cores.inside(np.array([START]))[0]
    r = _plan(threats, "auto", goal=(100.0, 0.0))
    assert r.status.value == "reached"
    assert r.escapes and r.escapes[0] == "leave core here"
    path = np.asarray(r.path)
    out = int(np.argmin(cores.inside(path)))  # the first point outside
    leave = float(np.hypot(*(path[out] - path[0])))
    assert leave <= 5.0 * math.sqrt(2 * math.log(2)) * 1.2 + 2 * r.params.step  # about the core's radius
    assert not cores.inside(path[out:]).any()


def test_an_escape_ending_at_the_goal_steers_on_to_it():
    from pfp_service.core.route import EscapeRun

    path = np.array([[float(k), 0.0] for k in range(11)])
    handed = EscapeRun("global", path, 1.0)
    kept = EscapeRun("global", path, 1.0, to_goal=True)
    for run in (handed, kept):
        run.direction(0.0, 0.0)
    assert handed.direction(9.6, 0.3) is None  # descent takes over
    d = kept.direction(9.6, 0.3)
    assert d is not None and d[0] > 0.7 and d[1] < 0  # on to the goal


def test_auto_goes_round_a_channel_that_descent_would_run_down():
    from benchmarks._cases import KINDS, generate
    from pfp_service.core.optimal import plan_optimal

    for case in [c for c in generate(2 * len(KINDS), 4) if c.kind == "corridor"]:
        sched = [Scheduled(t) for t in case.threats]
        plain, auto = (plan(case.start, case.goal, sched, PlannerParams(escape=m)) for m in ("none", "auto"))
        ref = plan_optimal(case.start, case.goal, sched, avoid_cores=True)
        j = lambda r: r.length + 10.0 * r.exposure
        assert auto.status.value == "reached" and not _core_entry(case.threats, auto.path)
        assert j(auto) <= min(j(plain) if plain.status.value == "reached" else math.inf, 1.10 * j(ref))


def test_optimal_with_avoid_cores_traps_an_enclosure_and_never_enters_a_core():
    from pfp_service.core.optimal import plan_optimal

    threats = ring()
    sched = [Scheduled(t) for t in threats]
    r = plan_optimal((20.0, 20.0), GOAL, sched, avoid_cores=True)
    assert r.status.value == "trapped" and "avoids the threat cores" in r.reason
    free = plan_optimal(START, GOAL, [Scheduled(t) for t in block()], avoid_cores=True)
    assert free.status.value == "reached" and not _core_entry(block(), free.path)


def _needle_wedge(sr=6.0, half_deg=30.0, tip=(65.0, 0.0)):
    out = []
    for side in (1.0, -1.0):
        a = math.radians(180.0 - side * half_deg)
        for k in range(4):
            d = (k + 0.5) * 1.6 * sr
            xy = (tip[0] + d * math.cos(a), tip[1] + d * math.sin(a))
            out.append(
                Threat.from_facing(
                    xy, (90.0 - math.degrees(a)) % 360, sr, 0.05 * sr, 20.0, 1.0, f"n{len(out)}"
                )
            )
    return out


def test_needles_in_a_wedge_are_resolved_and_gone_round():
    from pfp_service.core.escape_strategies import route_cell

    threats = _needle_wedge()
    r = _plan(threats, "auto", goal=(100.0, 0.0))
    assert r.status.value == "reached" and not _core_entry(threats, r.path)
    s_min = min(t.min_sigma() for t in threats)
    for span in (50.0, 160.0, 5000.0):
        fine, coarse = route_cell(span, s_min), route_cell(span, s_min, fine=False)
        assert fine <= coarse <= max(3.5 * s_min, span / 600)
        assert span / fine <= 600 + 1e-9


def test_routes_never_clip_a_sharply_skewed_core():
    """Pancakes with skew 10-50 have a rear far thinner than their sigmas: grid edges are re-checked densely."""
    from benchmarks._cases import KINDS, generate
    from pfp_service.core.optimal import plan_optimal

    cases = [c for c in generate(4 * len(KINDS), 7) if c.kind == "anisotropic"]
    for case in cases:
        sched = [Scheduled(t) for t in case.threats]
        r = plan(case.start, case.goal, sched, PlannerParams(escape="auto"))
        assert r.status.value == "reached" and not _core_entry(case.threats, r.path), case.name
        o = plan_optimal(case.start, case.goal, sched, avoid_cores=True)
        assert o.status.value == "reached" and not _core_entry(case.threats, o.path), case.name


def test_a_plan_that_starts_inside_a_core_says_so_in_its_events():
    t = Threat.from_facing((0.0, 0.0), 0.0, 10.0, 10.0, 0.0, 1.0, "e1")
    r = plan((1.0, 1.0), (100.0, 100.0), [Scheduled(t)], PlannerParams())
    assert r.status.value == "reached" and r.escapes[0] == "leave core e1"
    assert r.events[0] == "start inside the core of threat e1: left it by the shortest way out"
    clear = plan((60.0, 60.0), (100.0, 100.0), [Scheduled(t)], PlannerParams())
    assert not any("core" in e for e in clear.events)


@pytest.mark.parametrize("factor", [1.0, 0.5, 0.2, 0.05])
def test_the_contour_starts_where_the_trapped_descent_comes_to_rest_whatever_the_step(factor):
    """Descent is judged trapped about a step from the potential's minimum; the contour's level is the minimum's."""
    from scipy.optimize import minimize

    from pfp_service.core.escape_strategies import Trap, _settle

    threats = horseshoe()
    field = ThreatField(threats)
    base = resolve(PlannerParams(escape="none"), START, GOAL, threats)
    r = _plan(threats, "none", step=base.step * factor)
    assert r.status.value == "trapped"
    x, y = r.path[-1]
    gain = base.delta / math.dist(START, GOAL) ** 2

    def potential(v):
        return field.level_grad_at(v[0], v[1])[0] + gain * ((v[0] - GOAL[0]) ** 2 + (v[1] - GOAL[1]) ** 2)

    best = minimize(potential, [x, y], method="Nelder-Mead", options={"xatol": 1e-7, "fatol": 1e-12}).x
    step = base.step * factor
    tr = Trap(
        field, Cores(field), x, y, GOAL, base.delta, gain, step, base.tolerance, base.trap_window,
        math.dist((x, y), GOAL), 4 * step, 2000, None, np.random.default_rng(0),
    )  # fmt: skip
    sx, sy = _settle(tr)
    assert math.dist((sx, sy), best) <= step / 50, (factor, (x, y), (sx, sy), best)
    assert math.dist((sx, sy), best) < math.dist((x, y), best) or math.dist((x, y), best) <= step / 50
