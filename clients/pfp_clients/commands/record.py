"""``pfp record``, ``pfp replay`` and ``pfp report``: a mission record in MCAP, played back, summed up.

Exit codes: record 0 after SIGTERM, 130 after SIGINT (the file is finished
either way); replay 0 when the fresh planner gave the same directions, 1 when
some differ (each one named); report 0; any bad file or flag 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from pfp_service.cli._common import add_session_args, positive_float
from pfp_service.core.mobility import CLASSES

COMMANDS = ("record", "replay", "report")


# the help's example lines (cli.build_parser puts each under its parser)
EXAMPLES = {
    "record": "pfp record --mission exercise1 exercise1.mcap",
    "replay": "pfp replay exercise1.mcap --mission replay1 --speed-up 10",
    "report": "pfp report exercise1.mcap --out exercise1",
}


def register(sub: Any) -> None:
    p = sub.add_parser(
        "record",
        help="record every key of a mission into an MCAP file",
        description="Record every key of a mission (states, directions, goals, threats, zones, events, "
        "liveliness) into an MCAP file with the wire's JSON schemas, until SIGTERM or SIGINT. "
        "Example: pfp record --mission m1 m1.mcap",
    )
    p.add_argument("out", metavar="OUT.mcap", help="the file to write (replaced if it exists)")
    add_session_args(p)
    p.set_defaults(func=run_record)

    p = sub.add_parser(
        "replay",
        help="play a record's inputs onto a mission and compare the directions",
        description="Put a record's states, goals, threats and zones onto a mission on the recorded clock, "
        "and compare the directions a (fresh) planner gives with the recorded ones. "
        "Example: pfp replay m1.mcap --mission m1-replay --speed-up 5",
    )
    p.add_argument("record", metavar="RECORD.mcap", help="a file written by pfp record")
    add_session_args(p)
    p.add_argument("--speed-up", type=positive_float, default=1.0, help="recorded seconds per wall second")
    p.set_defaults(func=run_replay, mission=None)

    p = sub.add_parser(
        "report",
        help="an after-action summary of a record: table, plot, GeoJSON",
        description="Per unit: track, time, exposure, replans and their causes, as a table (stdout and CSV), "
        "a PNG plot and, when the record knows the origin, GeoJSON. Example: pfp report m1.mcap",
    )
    p.add_argument("record", metavar="RECORD.mcap", help="a file written by pfp record")
    p.add_argument(
        "--out",
        metavar="STEM",
        help="write STEM.csv, STEM.png and STEM.geojson (default: the record's path without .mcap, plus -report)",
    )
    p.add_argument(
        "--intensity", choices=("peak", "density"), default="peak", help="the field's scale for exposure"
    )
    p.add_argument(
        "--terrain",
        metavar="DEM",
        help="a DEM (GeoTIFF, DTED, SRTM .hgt) under the record: adds each unit's climb, max slope and "
        "time in view of each threat (needs the record's origin)",
    )
    p.add_argument(
        "--unit-class",
        choices=sorted(CLASSES),
        default="foot",
        help="the units' mobility class over --terrain: its height is what a threat must see (default foot)",
    )
    p.set_defaults(func=run_report)


def run_record(args: argparse.Namespace) -> int:
    import sys

    from pfp_clients.common import open_session_waiting
    from pfp_clients.record.coverage import describe
    from pfp_clients.record.recorder import record
    from pfp_service.cli._common import session_config
    from pfp_service.errors import InputError
    from pfp_service.signals import SignalStop

    out = Path(args.out)
    if out.suffix.lower() != ".mcap":
        raise InputError(args.out, "a record's name ends in .mcap")
    if not out.parent.is_dir():
        raise InputError(args.out, f"no such directory: {out.parent}")
    conf = session_config(args)
    with SignalStop() as stopping:
        session = open_session_waiting(conf, print, stopping.event)
        if session is None:
            return stopping.exit_code(1)
        with session:
            stats = record(session, args.mission, out, stopping.event, say=print)
    kinds = ", ".join(f"{n} {k}" for k, n in sorted(stats.by_kind.items()))
    print(
        f"pfp record: {stats.messages} messages ({kinds or 'none'}) in {stats.wall_s:.1f} s, "
        f"{stats.bytes / 1e6:.2f} MB, CPU {stats.cpu_s:.1f} s, largest batch {stats.max_backlog}",
        flush=True,
    )
    print(f"pfp record: {describe(stats.coverage)}", flush=True)
    if int(stats.coverage.get("missed_at_least", 0)) > 0:  # the router dropped them on this link (DROP)
        print(
            "pfp record: a planner's router dropped these on the way here; a planner or router with "
            "examples/zenoh-planner-recording.json5 (deeper transmit queues) records without loss "
            "(docs/clients.md, the mission record)",
            flush=True,
        )
    sys.stdout.flush()
    return stopping.exit_code(0)


def run_replay(args: argparse.Namespace) -> int:
    from pfp_clients.common import open_session_waiting
    from pfp_clients.record.mcapfile import read_record
    from pfp_clients.record.replay import replay, replay_inputs, result_lines
    from pfp_service.cli._common import session_config
    from pfp_service.errors import InputError
    from pfp_service.signals import SignalStop

    rec = read_record(args.record)
    mission = args.mission or rec.mission
    try:
        replay_inputs(rec, mission)  # refused before a session is opened
    except InputError as err:
        raise (InputError(Path(args.record).name, err.reason) if err.path == "record" else err) from None
    conf = session_config(args)
    with SignalStop() as stopping:
        session = open_session_waiting(conf, print, stopping.event)
        if session is None:
            return stopping.exit_code(1)
        with session:
            result = replay(session, rec, mission, args.speed_up, stopping.event)
    for line in result_lines(result):
        print(line)
    return stopping.exit_code(0 if result.ok else 1)


def run_report(args: argparse.Namespace) -> int:
    from pfp_clients.record.mcapfile import read_record

    rec = read_record(args.record)  # a hostile record is refused before the compiled core is imported
    ground = None
    if args.terrain is not None:
        from pfp_service.cli._common import require_extra
        from pfp_service.errors import InputError
        from pfp_service.terrain.dem import check

        require_extra("terrain", "rasterio")
        check(args.terrain)
        if rec.origin is None:
            raise InputError("--terrain", "the record has no origin: its metres cannot be placed on a DEM")
        ground = (args.terrain, CLASSES[args.unit_class])
    from pfp_clients.record.report import write_report

    src = Path(args.record)
    stem = Path(args.out) if args.out else src.with_name(src.stem + "-report")
    write_report(rec, stem, args.intensity, ground=ground)
    return 0
