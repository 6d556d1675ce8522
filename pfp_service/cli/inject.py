"""``pfp inject SCRIPT.yaml``: play a contingency script against the planner; exit 0 iff its expectations held."""

from __future__ import annotations

import argparse
from typing import Any

from pfp_service.cli._common import positive_float


def register(sub: Any) -> None:
    p = sub.add_parser(
        "inject", help="play a scripted contingency and check expectations", description=__doc__
    )
    p.add_argument("script", metavar="SCRIPT.yaml")
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router (default tcp/127.0.0.1:7447)"
    )
    p.add_argument("--mission", default="default")
    p.add_argument("--speed-up", type=positive_float, default=1.0, help="script seconds per wall second")
    p.add_argument("--check", action="store_true", help="validate the script and exit")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_clients.script import load_script

    from pfp_service.wire import keys

    keys.check_chunk(args.mission, "--mission")
    script = load_script(args.script)
    if args.check:
        print(f"{args.script}: ok, {len(script.timeline)} actions, {len(script.expect)} expectations")
        return 0
    from pfp_clients.inject import main

    return main(script, args.mission, args.speed_up, args.connect)
