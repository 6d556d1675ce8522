"""The look-ahead's simulation culls its gradients through the live tick's index (``cull``), and foresees the same."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks._layout import layout
from pfp_service.core import PlannerParams, ThreatField, cull, foresight, resolve
from pfp_service.world import translate

pytestmark = pytest.mark.unit


def test_culled_simulation_ends_as_the_full_one_among_many_threats(monkeypatch):
    lay = layout(40, 100, 7)
    field = ThreatField([translate.threat(u, t) for t, u in lay["threats"]])
    assert len(field) >= cull.MIN_THREATS and cull.index_of(field) is not None
    got, want = [], []
    for s, g in zip(lay["starts"][:40], lay["goals"][:40]):
        params = resolve(PlannerParams(step=1.0), s, g, list(field.threats))
        gain = params.delta / ((g[0] - s[0]) ** 2 + (g[1] - s[1]) ** 2)
        got.append(foresight.simulate(field, s, g, gain, params))
    monkeypatch.setattr(cull, "index_of", lambda f: None)  # every threat at every step, as before
    for s, g in zip(lay["starts"][:40], lay["goals"][:40]):
        params = resolve(PlannerParams(step=1.0), s, g, list(field.threats))
        gain = params.delta / ((g[0] - s[0]) ** 2 + (g[1] - s[1]) ** 2)
        want.append(foresight.simulate(field, s, g, gain, params))
    assert {w.outcome for w in want} >= {foresight.Outcome.ARRIVES, foresight.Outcome.TRAPPED}
    for a, b in zip(got, want):
        assert (a.outcome, a.steps) == (b.outcome, b.steps)
        assert np.hypot(a.x - b.x, a.y - b.y) <= 1e-6 * max(1.0, b.steps)
        assert a.exposure == pytest.approx(b.exposure, rel=1e-6, abs=1e-9)


def test_a_few_threats_are_simulated_without_an_index():
    lay = layout(1, 5, 7)
    field = ThreatField([translate.threat(u, t) for t, u in lay["threats"]])
    assert cull.index_of(field) is None
