"""``pfp bench quality`` in miniature: the suite is seeded and the report is honest."""

from __future__ import annotations

import math

from pfp_service.bench.cases import generate
from pfp_service.bench.quality import _pareto, measure_suite, render


def test_suite_is_seeded_and_spans_the_brief():
    a, b = generate(16, 5), generate(16, 5)
    assert [c.start for c in a] == [c.start for c in b]
    assert all(2 <= len(c.threats) <= 20 for c in a)
    assert all(10 <= math.dist(c.start, c.goal) <= 30_000 for c in a)
    assert {"horseshoe", "cup", "wall", "block", "enclosure-start", "enclosure-goal", "open"} <= {
        c.kind for c in a
    }


def test_pareto_gap_is_the_uniform_improvement_on_both_axes():
    assert _pareto(10.0, 1.0, [(9.0, 0.5), (12.0, 0.1)]) == (0.09999999999999998, 0.09999999999999998, 0.5)
    assert _pareto(10.0, 1.0, [(11.0, 0.5)])[0] == 0.0


def test_tiny_bench_run_reports_enclosures_honestly():
    rep = measure_suite(8, 11, ["none", "auto"], cells=60)
    auto = {r.case: r for r in rep.rows if r.mode == "auto"}
    for name in rep.enclosed:
        assert auto[name].status != "reached"
    assert all(not r.core_entry for r in auto.values() if r.status == "reached")
    assert all(r.j_ratio is not None and r.j_ratio > 0 for r in auto.values() if r.status == "reached")
    assert "| auto |" in render(rep, ["none", "auto"])
