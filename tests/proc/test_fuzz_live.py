"""``pfp bench fuzz`` in small: a real ``pfp serve`` takes 1,500+ malformed inputs and carries on."""

from __future__ import annotations

import pytest

from benchmarks.fuzz import fuzz

pytestmark = pytest.mark.proc


def test_a_planner_survives_malformed_input_on_every_key_and_queryable():
    seed = 7
    r = fuzz(count=300, seed=seed, say=lambda _: None)
    failed = [name for name, ok in r["checks"].items() if not ok]
    assert not failed, f"seed {seed}: {failed}; {r}"
    assert r["inputs"] >= 1500
    assert r["rejected"] + r["shed_overload"] == r["rejected_expected"] == 900 + 30  # 300 per key, 30 deletes
    q = r["queries"]
    # a preview or world query with bad parameters gets an error reply; status ignores parameters
    answered = {t: q.get(f"{t}_replies", 0) + q.get(f"{t}_error_replies", 0) for t in ("preview", "world")}
    assert answered["preview"] == q["status_replies"] == answered["world"] == 300, q
    assert q["world_error_replies"] > 0  # the odd selectors: "?a=b", "?" + 2,000 x, "?max_iter=1e99"
