"""``pfp fleet``: simulate a team of manned and unmanned vehicles that follow the planner's directions."""

from __future__ import annotations

import argparse
import signal
import threading
from typing import Any

from pfp_service.cli._common import positive_float, positive_int


def register(sub: Any) -> None:
    p = sub.add_parser("fleet", help="simulate a fleet of vehicles (a load source)", description=__doc__)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--team", metavar="YAML", help="team file: units with id, kind, start, goal, speed_mps")
    src.add_argument("--generate", type=positive_int, metavar="N", help="generate N units instead")
    p.add_argument("--seed", type=int, default=0, help="seed of the generated team (default 0)")
    p.add_argument("--area", type=positive_float, default=100.0, metavar="M", help="side of the square")
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router (default tcp/127.0.0.1:7447)"
    )
    p.add_argument("--mission", default="default")
    p.add_argument("--rate-hz", type=positive_float, default=5.0, help="state reports per simulated second")
    p.add_argument("--speed-up", type=positive_float, default=1.0, help="simulated seconds per wall second")
    p.add_argument("--duration-s", type=positive_float, metavar="S", help="stop after S simulated seconds")
    p.add_argument(
        "--until-arrived", action="store_true", help="stop when every unit arrived (exit 1 if not)"
    )
    p.add_argument("--no-goals", action="store_true", help="do not put the team's goals")
    p.add_argument(
        "--reply-timeout-s", type=positive_float, default=1.0, help="wait this long for late answers"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_clients.fleet import FleetOptions, main
    from pfp_clients.team import generate_team, load_team

    from pfp_service.wire import keys

    keys.check_chunk(args.mission, "--mission")
    team = load_team(args.team) if args.team else generate_team(args.generate, args.seed, args.area)
    opts = FleetOptions(
        mission=args.mission,
        rate_hz=args.rate_hz,
        speed_up=args.speed_up,
        duration_s=args.duration_s,
        until_arrived=args.until_arrived,
        set_goals=not args.no_goals,
        reply_timeout_s=args.reply_timeout_s,
    )
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    return main(team, opts, args.connect, stop)
