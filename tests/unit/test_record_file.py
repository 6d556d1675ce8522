"""The mission record's file, comparison and summary, in process: MCAP written and read back, replay's verdicts, report's sums."""

from __future__ import annotations

import json

import pytest
from pfp_clients.record.mcapfile import FIX_PREFIX, Entry, MissionWriter, Record, read_record
from pfp_clients.record.replay import Answer, compare, result_lines
from pfp_clients.record.report import summarise, table_rows

from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import keys

pytestmark = pytest.mark.unit
M = "m1"
ORIGIN = Origin(lat=58.4105, lon=15.6213, alt=90.0)
S = 1_000_000_000


def _state(x: float, y: float, seq: int) -> bytes:
    return json.dumps({"position": [x, y], "seq": seq}).encode()


def _direction(unit: str, seq: int, vector=(1.0, 0.0), status="en_route", deliberating=False) -> bytes:
    return json.dumps(
        {"unit": unit, "seq": seq, "status": status, "vector": list(vector), "deliberating": deliberating}
    ).encode()


def test_a_record_reads_back_as_written_with_its_schemas_and_fixes(tmp_path):
    from mcap.reader import make_reader

    path = tmp_path / "r.mcap"
    with path.open("wb") as f:
        w = MissionWriter(f, M, ORIGIN, 0)
        w.put(
            keys.threat(M, "e1"),
            json.dumps({"position": [5, 5], "sigma_range": 2, "sigma_lateral": 1}).encode(),
            1 * S,
        )
        w.put(keys.shard_state(M, "u10"), _state(0, 0, 1), 2 * S)
        w.put(keys.unit_direction(M, "u10"), _direction("u10", 1), 3 * S)
        w.delete(keys.threat(M, "e1"), 4 * S)
        w.alive(keys.alive_unit(M, "u10"), True, 2 * S)
        w.put("mumt/m1/something/else", b"{}", 5 * S)  # a key the contract does not know: kept, schemaless
        w.finish()
    rec = read_record(path)
    assert rec.mission == M and rec.origin == ORIGIN
    assert [(e.t_ns // S, e.data is None) for e in rec.entries] == [
        (1, False),
        (2, False),
        (3, False),
        (4, True),
        (5, False),
    ]
    assert rec.entries[3].key == keys.threat(M, "e1")
    assert rec.alive == [(2 * S, keys.alive_unit(M, "u10"), True)]
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        by_topic = {
            c.topic: reader.get_summary().schemas.get(c.schema_id)
            for c in reader.get_summary().channels.values()
        }
    assert json.loads(by_topic["/" + keys.unit_direction(M, "u10")].data)["title"]  # the contract's schema
    assert by_topic["/" + keys.shard_state(M, "u10")].name == "unit_state"
    assert by_topic[FIX_PREFIX + "u10"].name == "foxglove.LocationFix"
    assert by_topic["/mumt/m1/something/else"] is None


def test_a_file_that_is_not_a_record_is_one_clear_error(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\0" * 40)
    with pytest.raises(InputError) as e:
        read_record(bad)
    assert str(e.value).startswith("bad.mcap: not a readable mission record")
    with pytest.raises(InputError):
        read_record(tmp_path / "missing.mcap")


def _rec(entries: list[Entry]) -> Record:
    return Record(M, ORIGIN, entries, [])


def test_replay_compares_each_answered_state_and_names_the_differences():
    d = keys.unit_direction(M, "u1")
    rec = _rec(
        [
            Entry(1 * S, keys.unit_state(M, "u1"), _state(0, 0, 1)),
            Entry(1 * S + 1, d, _direction("u1", 1, deliberating=True)),
            Entry(2 * S, d, _direction("u1", 2)),
            Entry(3 * S, keys.threat(M, "e1"), b"{}"),
            Entry(4 * S, d, _direction("u1", 3, (0.0, 1.0))),
            Entry(5 * S, d, _direction("u1", 4, status="arrived")),
        ]
    )
    same = {
        ("u1", 1): Answer("en_route", (1.0, 0.0), True, ""),
        ("u1", 2): Answer("en_route", (1.0, 0.0), False, ""),
        ("u1", 3): Answer("en_route", (0.0, 1.0), False, ""),
        ("u1", 4): Answer("arrived", (1.0, 0.0), False, ""),
    }
    r = compare(rec, same, {})
    assert (r.compared, r.same, r.differences, r.ok) == (4, 4, [], True)
    assert result_lines(r)[-1] == "replay: the same directions"
    other = dict(same)
    other[("u1", 1)] = Answer("en_route", (1.0, 0.05), False, "")  # landed earlier, and turned 2.9 deg
    other[("u1", 3)] = Answer("en_route", (0.1, 1.0), False, "")  # turned 5.7 deg
    del other[("u1", 4)]
    r = compare(rec, other, {("u1", 3): (2.0, 3.0)})
    assert not r.ok and r.same == 1 and len(r.differences) == 3
    why = {d.seq: d.why for d in r.differences}
    assert "landed at another moment" in why[1]
    assert "after the unit's look-ahead landed (seq 2)" in why[3]
    assert why[4] == "the fresh planner never answered this state"
    assert r.max_turn_deg == pytest.approx(5.71, abs=0.01)
    assert "seq 3 at (2.00, 3.00)" in r.differences[1].line()


def test_report_sums_each_unit_in_natural_order():
    threat = json.dumps({"position": [5.0, 1.0], "sigma_range": 2.0, "sigma_lateral": 1.0}).encode()
    entries = [Entry(0, keys.threat(M, "e1"), threat)]
    for uid, y in (("u10", 0.0), ("u2", 10.0)):
        for i in range(11):
            entries.append(Entry(i * S, keys.unit_state(M, uid), _state(float(i), y, i)))
    entries.append(Entry(5 * S, keys.event(M, "replan"), json.dumps(
        {"kind": "replan", "units": ["u10"], "reason": "threat e1 put", "changes": [{"threat": "e1", "change": "put"}]}
    ).encode()))  # fmt: skip
    entries.append(Entry(10 * S, keys.unit_direction(M, "u10"), _direction("u10", 10, status="arrived")))
    rows, _watch = summarise(_rec(sorted(entries, key=lambda e: e.t_ns)))
    assert [u.unit for u in rows] == ["u2", "u10"]
    u2, u10 = rows
    assert u10.status == "arrived" and u10.time_s == pytest.approx(10.0) and u10.replans == 1
    assert u10.length_m == pytest.approx(10.0) and u10.min_clearance_m == pytest.approx(1.0)
    assert u10.exposure is not None and u2.exposure is not None and u10.exposure > u2.exposure > 0.0
    table = table_rows(rows)
    assert table[2][0] == "u10" and table[2][-1] == "put e1" and table[1][1] == "-"
