"""``pfp inject SCRIPT.yaml``: play a contingency script against the planner; exit 0 iff its expectations held."""

from __future__ import annotations

import argparse
from typing import Any

from pfp_service.cli._common import add_session_args, positive_float, session_config


def register(sub: Any) -> None:
    p = sub.add_parser(
        "inject", help="play a scripted contingency and check expectations", description=__doc__
    )
    p.add_argument("script", metavar="SCRIPT.yaml", help="the injection script")
    add_session_args(p)
    p.add_argument("--speed-up", type=positive_float, default=1.0, help="script seconds per wall second")
    p.add_argument("--check", action="store_true", help="validate the script and exit")
    p.add_argument(
        "--progress-s",
        type=positive_float,
        default=5.0,
        metavar="S",
        help="wall seconds between 'waiting on' lines when stdout is not a terminal",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_clients.script import load_script

    script = load_script(args.script)
    if args.check:
        print(f"{args.script}: ok, {len(script.timeline)} actions, {len(script.expect)} expectations")
        return 0
    from pfp_clients.inject import main
    from pfp_service.signals import SignalStop

    conf = session_config(args)
    with SignalStop() as stopping:  # 0 after SIGTERM, 130 after SIGINT, once the script has stopped
        code = main(script, args.mission, args.speed_up, conf, args.progress_s, stop=stopping.event)
    return stopping.exit_code(code)
