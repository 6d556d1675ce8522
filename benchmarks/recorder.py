"""The recorder under load: N units at R Hz for D seconds through a real planner, every message counted.

    python -m benchmarks.recorder --units 1000 --rate 10 --duration 60 [--out rec.mcap]

The planner (``pfp serve``) is the router, in its own process; ``pfp record``
runs in its own process as a client; this process is the load generator of
``pfp bench service`` (``bench._load.LoadGen``: every unit reports on its
shard key and moves along its direction).  Counted, not sampled:

* the planner's ``msgs_out`` (directions, events and missions it published,
  from its status before and after) against the record's directions, events
  and missions;
* the states sent against the record's states, and the directions the load
  generator (the units) got against those in the record: the same router
  serves both, so a loss in both is the overloaded planner's, not the recorder's;
* the recorder's CPU (from ``/proc``: all its threads) and the file's size, as
  MB per minute of mission.

Exit code 0 iff nothing was lost.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

PLANNER_OUT = ("unit_direction", "unit_mission", "event")


def _directions(path: Path) -> collections.Counter[tuple[str, int | None]]:
    """The record's directions as (unit, seq) with how often each came."""
    from mcap.reader import make_reader

    got: collections.Counter[tuple[str, int | None]] = collections.Counter()
    with path.open("rb") as f:
        for _schema, channel, msg in make_reader(f).iter_messages():
            if channel.topic.endswith("/direction"):
                d = json.loads(msg.data)
                got[(d["unit"], d.get("seq"))] += 1
    return got


def _coverage(path: Path) -> dict[str, object] | None:
    """What the record itself says it missed (its ``pfp.coverage`` metadata)."""
    from pfp_clients.record.mcapfile import read_record

    return read_record(path).coverage


def _count(path: Path) -> dict[str, int]:
    from mcap.reader import make_reader

    from pfp_service.errors import InputError
    from pfp_service.wire import keys

    counts: dict[str, int] = {}
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        channels = summary.channels
        for cid, n in summary.statistics.channel_message_counts.items():
            topic = channels[cid].topic
            if not topic.startswith(f"/{keys.PREFIX}/"):
                counts[topic] = counts.get(topic, 0) + n
                continue
            try:
                kind = keys.parse(topic[1:]).kind.value
            except InputError:
                kind = "other"
            counts[kind] = counts.get(kind, 0) + n
    return counts


def run(
    units: int, rate_hz: float, duration_s: float, out: Path, planner_zenoh: Path | None = None
) -> dict[str, Any]:
    """One run; ``planner_zenoh``: the planner's Zenoh JSON5 file (``PFP_ZENOH_CONFIG``), if any."""
    from benchmarks._load import MISSION, LoadGen, ProcMeter, start_server
    from benchmarks._phases import STEP_M
    from pfp_service.wire import Goal, keys

    saved = os.environ.get("PFP_ZENOH_CONFIG")
    if planner_zenoh is not None:
        os.environ["PFP_ZENOH_CONFIG"] = str(planner_zenoh)
    else:
        os.environ.pop("PFP_ZENOH_CONFIG", None)
    try:
        server = start_server("planner")
    finally:
        if saved is None:
            os.environ.pop("PFP_ZENOH_CONFIG", None)
        else:
            os.environ["PFP_ZENOH_CONFIG"] = saved
    rec_log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - closed below
    recorder = None
    gen = None
    try:
        starts = [(float(10 * (i % 100)), float(10 * (i // 100))) for i in range(units)]
        gen = LoadGen(server.endpoint, starts, STEP_M)
        gen.wait_ready()
        recorder = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", "record", "--connect", server.endpoint, "--mission", MISSION,
             str(out)],
            env={**os.environ, "PYTHONUNBUFFERED": "1"}, stdout=rec_log, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            rec_log.seek(0)
            if "pfp record: mission" in rec_log.read():
                break
            time.sleep(0.1)
        time.sleep(1.0)  # its subscriptions are declared once it has printed
        meter = ProcMeter(recorder.pid)
        for i, (x, y) in enumerate(starts):  # far goals: every unit en route all along
            gen.put_json(keys.unit_goal(MISSION, gen.ids[i]), Goal(position=(x, y + 100_000.0), step=STEP_M))
        time.sleep(1.0)
        before = gen.status() or {}
        cpu0 = meter.cpu_s() or 0.0
        seq0 = gen.seq
        _first, _end, sent_s = gen.pace(units * rate_hz, duration_s, list(range(units)))
        gen.settle(quiet_s=1.0, cap_s=10.0)
        cpu1 = meter.cpu_s() or 0.0
        after = gen.status() or {}
        states_sent = gen.seq - seq0
        units_got: collections.Counter[tuple[str, int | None]] = collections.Counter(
            (r.unit, r.seq) for r in gen.recv if r.seq is not None and r.seq >= seq0
        )
        recorder.send_signal(signal.SIGTERM)
        recorder.wait(timeout=300)
        rec_log.seek(0)
        rec_text = rec_log.read()
    finally:
        if recorder is not None and recorder.poll() is None:
            recorder.kill()
            recorder.wait()
        if gen is not None:
            gen.close()
        server.stop()
        rec_log.close()
    counts = _count(out)
    recorded = _directions(out)
    recorded = collections.Counter({k: n for k, n in recorded.items() if k[1] is not None and k[1] >= seq0})
    out_delta = int(after.get("msgs_out", 0)) - int(before.get("msgs_out", 0))
    recorded_out = sum(counts.get(k, 0) for k in PLANNER_OUT)
    size_mb = out.stat().st_size / 1e6
    return {
        "units": units,
        "rate_hz": rate_hz,
        "duration_s": round(sent_s, 1),
        "states_sent": states_sent,
        "states_recorded": counts.get("unit_state", 0),
        "planner_msgs_out": out_delta,
        "planner_out_recorded": recorded_out,
        "lost_planner_out": out_delta - recorded_out,
        "planner_msgs_in": int(after.get("msgs_in", 0)) - int(before.get("msgs_in", 0)),
        "directions_the_units_got": sum(units_got.values()),
        "directions_recorded": counts.get("unit_direction", 0),
        # matched by (unit, seq): lost on the recorder's link only, or on the units' link only
        "directions_only_the_record_lacks": sum((units_got - recorded).values()),
        "directions_only_the_units_lack": sum((recorded - units_got).values()),
        "planner_zenoh_config": str(planner_zenoh) if planner_zenoh is not None else None,
        "recorder_exit": recorder.returncode if recorder is not None else None,
        "recorder_cpu_s": round(cpu1 - cpu0, 1),
        "recorder_cpu_pct_of_a_core": round(100.0 * (cpu1 - cpu0) / max(sent_s, 1e-9), 1),
        "file_mb": round(size_mb, 1),
        "mb_per_min": round(size_mb / max(sent_s / 60.0, 1e-9), 1),
        "counts": counts,
        "recorder_says": [ln for ln in rec_text.splitlines() if ln.startswith("pfp record:")][-2:],
        "record_coverage": _coverage(out),
        "loadavg_1min": float(Path("/proc/loadavg").read_text().split()[0]),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.recorder", description=__doc__)
    p.add_argument("--units", type=int, default=1000)
    p.add_argument("--rate", type=float, default=10.0, help="reports per unit per second")
    p.add_argument("--duration", type=float, default=60.0, help="seconds of load")
    p.add_argument("--out", type=Path, help="the record (default: a temporary file, removed)")
    p.add_argument(
        "--planner-zenoh-config",
        type=Path,
        metavar="JSON5",
        help="the planner's Zenoh file, e.g. examples/zenoh-planner-recording.json5 (default: Zenoh's defaults)",
    )
    args = p.parse_args(argv)
    if args.planner_zenoh_config is not None and not args.planner_zenoh_config.is_file():
        p.error(f"--planner-zenoh-config: no such file: {args.planner_zenoh_config}")
    out = args.out or Path(tempfile.mkdtemp()) / "bench.mcap"
    result = run(args.units, args.rate, args.duration, out, args.planner_zenoh_config)
    print(json.dumps(result, indent=1))
    if args.out is None:
        out.unlink(missing_ok=True)
    lost = result["lost_planner_out"] != 0 or result["states_recorded"] != result["states_sent"]
    return 1 if lost else 0


if __name__ == "__main__":
    sys.exit(main())
