"""The stepper on its own: the contract both drivers rely on."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfp_service.core import PlannerParams, Stepper, StepStatus, Threat, ThreatField, resolve
from pfp_service.core.batch import advise_many

pytestmark = pytest.mark.unit


def _stepper(start=(0.0, 0.0), goal=(10.0, 10.0), threats=(), bounds=None, **kw):
    params = resolve(PlannerParams(**kw), start, goal, list(threats))
    return Stepper(start, goal, params, bounds), ThreatField(threats, params.intensity)


def test_no_threats_points_at_the_goal():
    s, field = _stepper()
    a = s.advise(field, 3.0, 1.0)
    assert a.status is StepStatus.EN_ROUTE
    assert math.isclose(a.dx, 7 / math.hypot(7, 9)) and math.isclose(a.dy, 9 / math.hypot(7, 9))
    assert a.level == 0.0 and math.isclose(a.distance, math.hypot(7, 9))


def test_arrival_bounds_and_invalid():
    s, field = _stepper(bounds=((-1.0, -1.0), (11.0, 11.0)))
    assert s.advise(field, 10.0, 10.05).status is StepStatus.ARRIVED
    assert s.advise(field, 20.0, 0.0).status is StepStatus.OUT_OF_BOUNDS
    a = s.advise(field, math.nan, 0.0)
    assert a.status is StepStatus.INVALID and (a.dx, a.dy) == (0.0, 0.0)


def test_symmetric_block_is_detected_as_a_trap():
    block = [Threat.from_facing((5.0, 5.0), 225.0, 1.0, 1.0, 0.0)]
    s, field = _stepper(threats=block, delta=0.05, escape="none")
    x, y = 0.0, 0.0
    for k in range(2000):
        a = s.advise(field, x, y)
        if a.status.terminal:
            break
        x, y = x + s.params.step * a.dx, y + s.params.step * a.dy
    assert a.status is StepStatus.TRAPPED
    assert k < 400 and a.reason
    # a trapped verdict stands until the world changes
    assert s.advise(field, x, y).status is StepStatus.TRAPPED
    s.world_changed()
    assert s.advise(ThreatField([]), x, y).status is StepStatus.EN_ROUTE


def test_advise_many_equals_advise_one_by_one():
    rng = np.random.default_rng(5)
    threats = [
        Threat.from_facing(rng.uniform(0, 10, 2), rng.uniform(0, 360), 1.0, 0.7, 2.0) for _ in range(6)
    ]
    field = ThreatField(threats)
    pos = rng.uniform(0, 10, (50, 2))
    goals = rng.uniform(0, 10, (50, 2))
    pos[3] = goals[3]  # one has arrived
    pos[7, 0] = math.nan  # one reports garbage
    params = resolve(PlannerParams(), (0.0, 0.0), (10.0, 10.0), threats)
    a = [Stepper((0.0, 0.0), tuple(g), params) for g in goals]
    b = [Stepper((0.0, 0.0), tuple(g), params) for g in goals]
    batch = advise_many(a, field, pos)
    single = [s.advise(field, *p) for s, p in zip(b, pos)]
    assert [a._replace(distance=0.0) for a in batch] == [a._replace(distance=0.0) for a in single]
    assert [a.distance for a in batch if not math.isnan(a.distance)] == [
        a.distance for a in single if not math.isnan(a.distance)
    ]
    assert batch[3].status is StepStatus.ARRIVED and batch[7].status is StepStatus.INVALID


def test_advise_many_asks_a_deferred_look_ahead_as_advise_does():
    """After a change of the world, deferring steppers (the live wave) give what ``advise`` gives, one by one.

    The batch judges such a unit in one call (``Stepper.foresee_follow``);
    one arrived, one out of bounds and one reporting garbage keep their
    verdict without asking the look-ahead, as ``check`` then ``follow`` do.
    """
    rng = np.random.default_rng(11)
    threats = [
        Threat.from_facing(rng.uniform(0, 10, 2), rng.uniform(0, 360), 1.0, 0.7, 2.0) for _ in range(6)
    ]
    field = ThreatField(threats)
    pos = rng.uniform(0, 10, (40, 2))
    goals = rng.uniform(0, 10, (40, 2))
    pos[3] = goals[3]  # arrived
    pos[5] = (30.0, 5.0)  # out of bounds
    pos[7, 0] = math.nan  # garbage
    params = resolve(PlannerParams(escape="auto"), (0.0, 0.0), (10.0, 10.0), threats)
    bounds = ((-1.0, -1.0), (11.0, 11.0))

    def steppers() -> list[Stepper]:
        out = []
        for g, p in zip(goals, pos):
            s = Stepper((0.0, 0.0), tuple(g), params, bounds)
            s.defer = True
            s.advise(field, *np.nan_to_num(p) % 10.0)  # asks its first look-ahead
            s.pending = None
            s.world_changed()  # the wave: look ahead again
            out.append(s)
        return out

    a, b = steppers(), steppers()
    batch = advise_many(a, field, pos)
    single = [s.advise(field, *p) for s, p in zip(b, pos)]
    assert [x._replace(distance=0.0) for x in batch] == [x._replace(distance=0.0) for x in single]
    assert [x.distance for x in batch][8:] == [x.distance for x in single][8:]
    assert [(s.pending, s.advisories) for s in a] == [(s.pending, s.advisories) for s in b]
    assert batch[3].status is StepStatus.ARRIVED and a[3].pending is None
    assert batch[5].status is StepStatus.OUT_OF_BOUNDS and a[5].pending is None
    assert batch[7].status is StepStatus.INVALID and a[7].pending is None
    assert all(x.deliberating for i, x in enumerate(batch) if i not in (3, 5, 7))
    again = [s.advise(field, *p) for s, p in zip(a, pos)]  # the watch went on alike
    alike = [s.advise(field, *p) for s, p in zip(b, pos)]
    assert again[:7] + again[8:] == alike[:7] + alike[8:]


def _trapped_stepper():
    block = [Threat.from_facing((5.0, 5.0), 225.0, 1.0, 1.0, 0.0)]
    params = resolve(PlannerParams(delta=0.05, escape="none"), (0.0, 0.0), (10.0, 10.0), block)
    s, field = Stepper((0.0, 0.0), (10.0, 10.0), params), ThreatField(block)
    x, y = 0.0, 0.0
    for _ in range(2000):
        a = s.advise(field, x, y)
        if a.status.terminal:
            break
        x, y = x + params.step * a.dx, y + params.step * a.dy
    assert a.status is StepStatus.TRAPPED
    return s, field, x, y


def test_trapped_verdict_reports_the_position_it_is_asked_about():
    s, field, x, y = _trapped_stepper()
    nudge = 0.5 * s.params.step * s.params.trap_window  # still near the trap
    a = s.advise(field, x + nudge, y)
    assert a.status is StepStatus.TRAPPED
    assert math.isclose(a.distance, math.hypot(10.0 - x - nudge, 10.0 - y))
    assert math.isclose(a.level, field.level_grad_at(x + nudge, y)[0])


def test_trapped_unit_walked_away_is_guided_again():
    s, field, _x, _y = _trapped_stepper()
    a = s.advise(field, 9.0, 4.0)  # carried round the block
    assert a.status is StepStatus.EN_ROUTE
    assert math.isclose(a.distance, math.hypot(1.0, 6.0))
    s2, field, x, y = _trapped_stepper()
    (b,) = advise_many([s2], field, np.array([[9.0, 4.0]]))
    assert b == a
    (c,) = advise_many([_trapped_stepper()[0]], field, np.array([[x, y]]))
    assert c.status is StepStatus.TRAPPED and math.isclose(c.level, field.level_grad_at(x, y)[0])


def test_route_ahead_is_what_a_ghost_walks():
    """The compiled look-ahead along a committed route gives a ghost's own track, point for point."""
    from pfp_service.core.plan import walk_many
    from tests.routed_fleet import walk

    compared = ended = 0
    for w, ids, pos in walk(40, 80):
        for u, (x, y) in zip(ids, pos.tolist()):
            s = w.view(u).stepper
            if s is None or not s.escaping:
                continue
            ahead = s.route_ahead(x, y, 6)
            ghost = walk_many([s.ghost()], w.field, np.array([[x, y]]), 6)[0]
            if ahead is None:  # the route may end within the steps: the caller walks a ghost
                ended += 1
                continue
            compared += 1
            assert len(ahead) == len(ghost)
            assert np.allclose(ahead, ghost, rtol=0.0, atol=1e-9)
    assert compared > 500, (compared, ended)  # the layout keeps most units on routes
