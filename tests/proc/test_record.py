"""``pfp record``, ``pfp replay`` and ``pfp report`` on a real mission: planner, fleet and script as subprocesses."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from tests.conftest import ROOT, run_pfp
from tests.zenoh_util import client, planner_process

ORIGIN = "58.4105,15.6213,90"
TEAM = """\
name: small
units:
  - {id: m1, kind: manned, start: [0, 10], goal: [30, 14], speed_mps: 1.5}
  - {id: r1, kind: unmanned, start: [0, 2], goal: [30, 4], speed_mps: 3.0}
"""
SCRIPT = """\
name: small
duration_s: 60
timeline:
  - {do: add_threat, threat: e1, position: [15, 8], facing_deg: 270, sigma_range: 3, sigma_lateral: 2, skew: 1}
  - do: add_threat
    when: {unit: m1, within_m: 2, of: [8, 11]}
    threat: e2
    position: [18, 15]
    facing_deg: 270
    sigma_range: 2
    sigma_lateral: 1.5
  - {do: wait, seconds: 3}
  - {do: move_threat, threat: e2, position: [18, 17]}
expect:
  - {unit: m1, arrives_within_s: 40}
  - {unit: r1, arrives_within_s: 30}
"""
PLANNER_OUT = ("unit_direction", "unit_mission", "event")


def _popen(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _wait_line(proc: subprocess.Popen[str], needle: str, timeout: float = 30.0) -> str:
    deadline = time.monotonic() + timeout
    seen = []
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        seen.append(line)
        if needle in line:
            return line
    raise AssertionError(f"no {needle!r} in {seen}")


def _msgs_out(endpoint: str, mission: str) -> int:
    with client(endpoint) as s:
        for r in s.get(f"mumt/{mission}/planner/*/status", timeout=5.0):
            if r.ok is not None:
                return int(json.loads(r.ok.payload.to_bytes())["msgs_out"])
    raise AssertionError("no status")


def _validate(path: Path) -> dict[str, int]:
    """The mcap library's own reader with every CRC checked; each message's JSON parses; counts by key kind."""
    from mcap.reader import make_reader

    from pfp_service.wire import keys

    counts: dict[str, int] = {}
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        n = 0
        for schema, channel, msg in reader.iter_messages():
            n += 1
            assert channel.message_encoding == "json"
            json.loads(msg.data)
            if schema is not None:
                assert schema.encoding == "jsonschema" and json.loads(schema.data)
            if channel.topic.startswith("/mumt/"):
                kind = keys.parse(channel.topic[1:]).kind.value
                counts[kind] = counts.get(kind, 0) + 1
        assert n == summary.statistics.message_count
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert "origin" in meta["pfp"]
    return counts


@pytest.mark.multi
@pytest.mark.alone
def test_record_replay_report_a_mission(tmp_path):
    mission = "r" + uuid.uuid4().hex[:10]
    team, script, rec = tmp_path / "team.yaml", tmp_path / "script.yaml", tmp_path / "m.mcap"
    team.write_text(TEAM)
    script.write_text(SCRIPT)
    with planner_process("--origin", ORIGIN, mission=mission) as (endpoint, _):
        before = _msgs_out(endpoint, mission)
        recorder = _popen("record", "--connect", endpoint, "--mission", mission, str(rec))
        try:
            _wait_line(recorder, "pfp record: mission")
            inject = _popen(
                "inject", str(script), "--connect", endpoint, "--mission", mission, "--speed-up", "5"
            )
            fleet = run_pfp(
                "fleet", "--team", str(team), "--connect", endpoint, "--mission", mission,
                "--speed-up", "5", "--until-arrived", timeout=180,
            )  # fmt: skip
            assert fleet.returncode == 0, fleet.stdout[-2000:] + fleet.stderr[-2000:]
            out, _ = inject.communicate(timeout=120)
            assert inject.returncode == 0, out[-2000:]
            time.sleep(1.0)  # the last pushes and events
            after = _msgs_out(endpoint, mission)
        finally:
            recorder.send_signal(signal.SIGTERM)
            rest, _ = recorder.communicate(timeout=60)
        assert recorder.returncode == 0, rest
        assert re.search(r"pfp record: \d+ messages .* MB, CPU", rest), rest
    counts = _validate(rec)
    assert counts["unit_state"] > 20 and counts["unit_direction"] > 20  # a loaded planner may skip late ones
    assert counts["threat"] == 3 and counts["unit_goal"] == 2
    # nothing the planner sent was lost: every message it counted is in the record (the record runs on
    # a little after `after` was asked, so it may hold a late push more; its own verdict below is exact)
    assert sum(counts.get(k, 0) for k in PLANNER_OUT) >= after - before, counts
    # and the record says so itself, from the planner's counters it asked at its start and end
    from pfp_clients.record.mcapfile import read_record

    cov = read_record(rec).coverage
    assert cov is not None and cov["counted"] and cov["planners"] == 1, cov
    assert cov["published"] >= after - before and cov["missed_at_least"] == 0, cov
    assert "pfp record: planner outputs: " in rest and "missed" in rest, rest

    # a fresh planner, the same inputs: the same directions, or each difference named with its cause
    with planner_process("--origin", ORIGIN, mission=mission + "b") as (endpoint, _):
        r = run_pfp(
            "replay",
            str(rec),
            "--connect",
            endpoint,
            "--mission",
            mission + "b",
            "--speed-up",
            "5",
            timeout=240,
        )
    text = r.stdout
    m = re.search(r"(\d+) recorded directions compared, (\d+) the same, (\d+) differ", text)
    assert m, text[-3000:] + r.stderr[-2000:]
    compared, same, differ = map(int, m.groups())
    assert compared >= counts["unit_state"] - 2 and same + differ == compared
    if differ:
        assert r.returncode == 1 and "DIFFERENT directions" in text
        assert re.search(r"by at most ([\d.e+-]+) deg; \d+ in status; 0 unanswered", text), text[-3000:]
        assert all(": " in ln for ln in text.splitlines() if ln.startswith("  t="))
    else:
        assert r.returncode == 0 and "replay: the same directions" in text

    stem = tmp_path / "aar"
    r = run_pfp("report", str(rec), "--out", str(stem), timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "unit  status" in r.stdout
    # the record says what it lacks: nothing of the planner's, no state of either unit (fleet counts seq one by one)
    assert "record: planner outputs: " in r.stdout and "none missed" in r.stdout, r.stdout[:2000]
    assert "record: states: none missing by their seq (2 units)" in r.stdout, r.stdout[:2000]
    rows = list(csv.reader((tmp_path / "aar.csv").open()))
    assert rows[0][:4] == ["unit", "status", "time s", "path m"]
    by_unit = {row[0]: row for row in rows[1:]}
    assert set(by_unit) == {"m1", "r1"}
    for row in by_unit.values():
        assert row[1] == "arrived" and float(row[3]) > 25 and float(row[4]) >= 0
    assert int(by_unit["m1"][6]) >= 1 and "e2" in by_unit["m1"][7]  # the pop-up threat re-planned m1
    assert (tmp_path / "aar.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    gj = json.loads((tmp_path / "aar.geojson").read_text())
    tracks = [f for f in gj["features"] if f["properties"]["kind"] == "track"]
    assert {f["properties"]["unit"] for f in tracks} == {"m1", "r1"}
    lon, lat = tracks[0]["geometry"]["coordinates"][-1]
    assert abs(lat - 58.4105) < 0.001 and abs(lon - 15.6213) < 0.001


@pytest.mark.proc
def test_record_stops_on_sigint_with_a_whole_file(tmp_path):
    mission = "r" + uuid.uuid4().hex[:10]
    rec = tmp_path / "idle.mcap"
    with planner_process(mission=mission) as (endpoint, _):
        recorder = _popen("record", "--connect", endpoint, "--mission", mission, str(rec))
        _wait_line(recorder, "pfp record: mission")
        recorder.send_signal(signal.SIGINT)
        out, _ = recorder.communicate(timeout=60)
    assert recorder.returncode == 130, out
    assert re.search(r"pfp record: planner outputs: \d+ published by 1 planner\(s\) while recording", out), (
        out
    )
    from mcap.reader import make_reader

    with rec.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_summary() is not None
        list(reader.iter_messages())


@pytest.mark.proc
def test_bad_record_files_are_one_line_exit_2(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    r = run_pfp("report", str(junk))
    assert r.returncode == 2 and r.stderr.startswith("pfp report: junk.mcap: not a readable mission record")
    assert "Traceback" not in r.stderr
    r = run_pfp("record", str(tmp_path / "x.txt"))
    assert r.returncode == 2 and "x.txt: a record's name ends in .mcap" in r.stderr


@pytest.mark.proc
def test_the_record_bench_counts_every_message_with_the_recording_planner_file(tmp_path):
    """A small load through a planner given examples/zenoh-planner-recording.json5: nothing lost, and
    the record's own verdict agrees with the bench's count."""
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.recorder",
        "--units",
        "40",
        "--rate",
        "5",
        "--duration",
        "3",
    ]
    r = subprocess.run(
        [*cmd, "--planner-zenoh-config", str(ROOT / "examples" / "zenoh-planner-recording.json5")],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    res = json.loads(r.stdout)
    assert res["states_sent"] > 100 and res["states_recorded"] == res["states_sent"]
    assert res["planner_msgs_out"] > 0 and res["lost_planner_out"] == 0
    assert res["directions_only_the_record_lacks"] == 0
    cov = res["record_coverage"]
    assert cov["counted"] and cov["missed_at_least"] == 0 and cov["published"] >= res["planner_msgs_out"]
    bad = subprocess.run([*cmd, "--planner-zenoh-config", str(tmp_path / "nope.json5")],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert bad.returncode == 2 and "--planner-zenoh-config: no such file" in bad.stderr
    assert "Traceback" not in bad.stderr
