"""What a record says it missed of the planners' outputs: ``Coverage`` fed by hand, and its metadata read back."""

from __future__ import annotations

import io

import pytest
from pfp_clients.record.coverage import Counted, Coverage, describe, describe_gaps, seq_gaps
from pfp_clients.record.mcapfile import MissionWriter, read_record

pytestmark = pytest.mark.unit
P = ("planner", "zid1")


def _run(
    published: int, times: list[int], kind: str = "unit_direction", after: tuple[int, ...] = ()
) -> dict[str, object]:
    """``times`` drained before the last question, ``after`` while the recorder settles after it."""
    cov = Coverage()
    cov.begin(Counted({P: 100}, asked_ns=10, answered_ns=20))
    for t in times:
        cov.seen(kind, t)
    cov.end(Counted({P: 100 + published}, asked_ns=1000, answered_ns=1010))
    for t in after:
        cov.seen(kind, t)
    return cov.result()


def test_every_output_inside_the_answers_is_none_missed():
    r = _run(3, [100, 200, 300])
    assert r["counted"] and r["published"] == 3 and r["recorded"] == 3
    assert r["missed_at_least"] == 0 and r["missed_at_most"] == 0
    assert describe(r).endswith("none missed")


def test_a_missing_output_is_counted_and_the_edges_bound_it():
    # 4 published; one certainly inside is gone; one came while the first question was out
    r = _run(4, [15, 100, 300])
    assert r["recorded"] == 2 and r["recorded_at_the_edges"] == 1
    assert (r["missed_at_least"], r["missed_at_most"]) == (1, 2)
    assert "1 to 2 missed" in describe(r)
    r = _run(3, [100, 300])
    assert (r["missed_at_least"], r["missed_at_most"]) == (1, 1) and "1 missed" in describe(r)


def test_only_planner_outputs_and_only_between_the_answers_count():
    r = _run(1, [5, 500], after=(2000,))  # before the first question, inside, after the last answer
    assert r["recorded"] == 1 and r["recorded_at_the_edges"] == 0 and r["missed_at_most"] == 0
    r = _run(2, [500], after=(990, 1005))  # published before the last answer, drained after it
    assert r["recorded"] == 2 and r["recorded_at_the_edges"] == 1 and r["missed_at_least"] == 0
    r = _run(1, [500], kind="unit_state")  # states are not the planner's msgs_out
    assert r["recorded"] == 0 and r["missed_at_least"] == 1


def test_no_planner_or_a_changed_planner_is_not_counted():
    cov = Coverage()
    cov.begin(Counted({}, 0, 1))
    cov.end(Counted({P: 5}, 2, 3))
    assert cov.result()["counted"] is False
    cov = Coverage()
    cov.begin(Counted({P: 5}, 0, 1))
    cov.end(Counted({("planner", "zid2"): 9}, 2, 3))  # restarted: another session, a new counter
    r = cov.result()
    assert r["counted"] is False and "changed" in describe(r)


def test_the_verdict_is_in_the_file_metadata(tmp_path):
    path = tmp_path / "r.mcap"
    buf = io.BytesIO()
    w = MissionWriter(buf, "m1", None, 0)
    cov = Coverage()
    cov.begin(Counted({P: 0}, 0, 1))
    cov.seen(w.put("mumt/m1/unit/u1/direction", b'{"unit": "u1", "seq": 1}', 5), 5)
    cov.end(Counted({P: 2}, 10, 11))
    w.coverage(cov.result())
    w.finish()
    path.write_bytes(buf.getvalue())
    rec = read_record(path)
    assert rec.coverage is not None
    assert rec.coverage["published"] == 2 and rec.coverage["missed_at_least"] == 1


def test_states_missing_by_their_seq():
    assert seq_gaps([1, 2, 3, 4]) == 0
    assert seq_gaps([1, 2, 4, 5, 8]) == 3
    assert seq_gaps([3, 4, 4, 5]) == 0  # a state recorded twice (plain and shard key) is not a gap
    assert seq_gaps([10, 11, 13, 0, 1, 3]) == 2  # restarted at 0: each run counted on its own
    assert seq_gaps([0, 1000, 2000, 3000]) is None  # a shared counter: gaps say nothing
    line = describe_gaps({"u1": 0, "u2": 2, "u10": 1, "x": None})
    assert line == "states: 3 missing by their seq (u2: 2, u10: 1)"
    assert describe_gaps({"u1": 0}) == "states: none missing by their seq (1 units)"
    assert "not counted" in describe_gaps({"x": None})
