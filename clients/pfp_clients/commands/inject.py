"""``pfp inject FILE``: play a contingency script, or a scenario, against the planner; exit 0 iff it held.

FILE is an injection script (``timeline:`` and ``expect:``), or a scenario
file as ``pfp plan`` takes it (``start``, ``goal``, ``threats``): its threats
are put, its unit (``--unit``) gets the goal and, unless ``--no-sim``, a
simulated unit drives from the start; the live track is then judged against
the plan of the same file.
"""

from __future__ import annotations

import argparse
from typing import Any

from pfp_service.cli._common import add_coords_arg, add_session_args, positive_float, session_config

# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"inject": "pfp inject examples/demo-inject.yaml --speed-up 4"}


def register(sub: Any) -> None:
    p = sub.add_parser(
        "inject", help="play a scripted contingency and check expectations", description=__doc__
    )
    p.add_argument("script", metavar="FILE", help="the injection script, or a scenario file")
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
    add_coords_arg(p)
    s = p.add_argument_group("a scenario file")
    s.add_argument("--unit", default="u1", metavar="ID", help="the unit that drives the scenario")
    s.add_argument(
        "--rate-hz",
        type=positive_float,
        default=5.0,
        metavar="HZ",
        help="the simulated unit's reports a second",
    )
    s.add_argument(
        "--no-sim", action="store_true", help="only put threats and the goal: a real unit at the start drives"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_clients.live_scenario import is_scenario_file
    from pfp_clients.script import load_script

    if is_scenario_file(args.script):
        return _scenario(args)

    script = load_script(args.script)
    if args.check:
        print(f"{args.script}: ok, {len(script.timeline)} actions, {len(script.expect)} expectations")
        return 0
    from pfp_clients.inject import main
    from pfp_service.signals import SignalStop

    conf = session_config(args)
    with SignalStop() as stopping:  # 0 after SIGTERM, 130 after SIGINT, once the script has stopped
        code = main(
            script,
            args.mission,
            args.speed_up,
            conf,
            args.progress_s,
            stop=stopping.event,
            coords=args.coords,
        )
    return stopping.exit_code(code)


def _scenario(args: argparse.Namespace) -> int:
    from pfp_clients.live_scenario import live_scenario, play

    ls = live_scenario(args.script, args.unit, args.rate_hz)
    if args.check:
        print(
            f"{args.script}: ok, a scenario: {len(ls.script.timeline)} actions, unit {ls.unit}, "
            f"the plan {ls.plan_status} in {len(ls.plan_path) - 1} steps"
        )
        return 0
    from pfp_service.signals import SignalStop

    conf = session_config(args)
    with SignalStop() as stopping:
        code = play(conf, ls, args.mission, args.speed_up, stop=stopping.event, sim=not args.no_sim)
    return stopping.exit_code(code)
