"""``pfp bench fuzz`` in small, as a user runs it: a real ``pfp serve`` takes 1,500+ malformed inputs and carries on.

The docs show ``pfp bench fuzz``; this test runs that line (at 300 inputs a key)
for the docs test (``tests/multi/test_docs.py``, ``RUN_ELSEWHERE``).
"""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_pfp

pytestmark = pytest.mark.proc


def test_a_planner_survives_malformed_input_on_every_key_and_queryable():
    seed = 7
    done = run_pfp("bench", "fuzz", "--count", "300", "--seed", str(seed), "--json", timeout=400)
    assert done.returncode in (0, 1) and "Traceback" not in done.stderr, done.stderr[-3000:]
    r = json.loads(done.stdout)
    failed = [name for name, ok in r["checks"].items() if not ok]
    assert not failed and done.returncode == 0, f"seed {seed}: {failed}; {r}"
    assert r["inputs"] >= 1500
    assert r["rejected"] + r["shed_overload"] == r["rejected_expected"] == 900 + 30  # 300 per key, 30 deletes
    q = r["queries"]
    # a preview or world query with bad parameters gets an error reply; status ignores parameters
    answered = {t: q.get(f"{t}_replies", 0) + q.get(f"{t}_error_replies", 0) for t in ("preview", "world")}
    assert answered["preview"] == q["status_replies"] == answered["world"] == 300, q
    assert q["world_error_replies"] > 0  # the odd selectors: "?a=b", "?" + 2,000 x, "?max_iter=1e99"
