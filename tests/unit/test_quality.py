"""``pfp bench quality`` in miniature: the suite is seeded and the report is honest."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks._cases import KINDS, generate, reachability
from benchmarks.quality import _pareto, measure_suite, render
from pfp_service.core import ThreatField
from pfp_service.core.cores import Cores

pytestmark = pytest.mark.unit


def test_suite_is_seeded_and_spans_the_brief():
    a, b = generate(len(KINDS), 5), generate(len(KINDS), 5)
    assert [c.start for c in a] == [c.start for c in b]
    assert [c.threats for c in a] == [c.threats for c in b]
    assert {c.kind for c in a} == set(KINDS)
    for c in a:
        d0 = math.dist(c.start, c.goal)
        assert (10_000 <= d0 <= 30_000) if c.kind == "clutter" else (10 <= d0 <= 30_000)
        assert (200 <= len(c.threats) <= 1000) if c.kind == "clutter" else (2 <= len(c.threats) <= 60)
        assert not Cores(ThreatField(c.threats)).inside(np.array([c.start, c.goal])).any()
        if c.bounds is not None:
            (x0, y0), (x1, y1) = c.bounds
            assert all(x0 <= p[0] <= x1 and y0 <= p[1] <= y1 for p in (c.start, c.goal))
    aniso = [c for c in a if c.kind == "anisotropic"]
    assert all(max((t.spread() / t.min_sigma()) ** 2 for t in c.threats) >= 8 for c in aniso)


def test_ground_truth_is_the_generators_intent_on_the_clear_cases():
    for c in generate(2 * len(KINDS), 8):
        if c.kind in (
            "enclosure-start",
            "enclosure-goal",
            "ring-shut",
            "ring-open",
            "gap-open",
            "wall",
            "cup",
        ):
            v = reachability(c)
            assert v.reachable is (not c.enclosed), c.name


def test_pareto_gap_is_the_uniform_improvement_on_both_axes():
    assert _pareto(10.0, 1.0, [(9.0, 0.5), (12.0, 0.1)]) == (0.09999999999999998, 0.09999999999999998, 0.5)
    assert _pareto(10.0, 1.0, [(11.0, 0.5)])[0] == 0.0


def test_tiny_bench_run_reports_enclosures_honestly():
    rep = measure_suite(8, 11, ["none", "auto"], cells=60)
    auto = {r.case: r for r in rep.rows if r.mode == "auto"}
    for name in rep.enclosed:
        assert auto[name].status != "reached"
    assert all(not r.core_entry for r in auto.values() if r.status == "reached")
    assert all(
        r.j_ratio is not None and r.j_ratio > 0
        for r in auto.values()
        if r.status == "reached" and r.case in rep.reachable
    )
    text = render(rep, ["none", "auto"])
    assert "| auto |" in text and "J / J* median" in text
