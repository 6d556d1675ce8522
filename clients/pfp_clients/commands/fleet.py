"""``pfp fleet``: simulate a team of manned and unmanned vehicles that follow the planner's directions."""

from __future__ import annotations

import argparse
import math
from typing import Any

from pfp_service.cli._common import (
    add_coords_arg,
    add_session_args,
    positive_float,
    positive_int,
    session_config,
)
from pfp_service.core.mobility import CLASSES
from pfp_service.signals import SignalStop

# Each unit costs a publisher, a token and a Python object per tick: past this one fleet process
# cannot keep up (ZENOH-NOTES: ~10 000 updates/s per process), so run several instead.
MAX_GENERATE = 10_000


def generated_units(text: str) -> int:
    """``--generate N``: 1 to ``MAX_GENERATE`` units."""
    value = positive_int(text)
    if value > MAX_GENERATE:
        raise argparse.ArgumentTypeError(
            f"at most {MAX_GENERATE} units per fleet process, got {text!r} (run several fleets instead)"
        )
    return value


def gps_sigma(text: str) -> float:
    """``--gps-sigma-m``: 0 to 100 metres."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected metres from 0 to 100, got {text!r}") from None
    if not 0.0 <= value <= 100.0:
        raise argparse.ArgumentTypeError(f"expected metres from 0 to 100, got {text!r}")
    return value


def stops(text: str) -> tuple[tuple[float, float], ...]:
    """``--stops 20:15,60:10``: halts as (at_s, for_s), each at >= 0 s and for > 0 s."""
    out = []
    for part in text.split(","):
        at, sep, dur = part.partition(":")
        try:
            pair = (float(at), float(dur))
        except ValueError:
            pair = (math.nan, math.nan)
        if not sep or not (0.0 <= pair[0] <= 1e7 and 0.0 < pair[1] <= 1e7):
            raise argparse.ArgumentTypeError(f"expected AT:FOR seconds (AT >= 0, FOR > 0), got {part!r}")
        out.append(pair)
    if len(out) > 1000:
        raise argparse.ArgumentTypeError("at most 1000 stops")
    return tuple(out)


# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"fleet": "pfp fleet --team examples/demo-team.yaml --speed-up 10 --until-arrived"}


def register(sub: Any) -> None:
    p = sub.add_parser("fleet", help="simulate a fleet of vehicles (a load source)", description=__doc__)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--team", metavar="YAML", help="team file: units with id, kind, start, goal, speed_mps")
    src.add_argument(
        "--generate",
        type=generated_units,
        metavar="N",
        help=f"generate N units instead (1 to {MAX_GENERATE})",
    )
    p.add_argument("--seed", type=int, help="seed of the generated team (default: 0)")
    p.add_argument(
        "--area", type=positive_float, metavar="M", help="side of the generated square in m (default: 100)"
    )
    add_session_args(p)
    p.add_argument(
        "--rate-hz",
        type=positive_float,
        default=5.0,
        help="state reports per simulated second, of each unit without its own rate_hz (default: 5)",
    )
    p.add_argument(
        "--gps-sigma-m",
        type=gps_sigma,
        default=0.0,
        metavar="M",
        help="each reported fix is off by a Gaussian of M metres per axis, unless the unit says (default: 0)",
    )
    p.add_argument(
        "--stops",
        type=stops,
        default=(),
        metavar="AT:FOR[,AT:FOR...]",
        help="every unit without its own stops halts AT simulated seconds in, for FOR seconds",
    )
    p.add_argument(
        "--mobility",
        choices=tuple(CLASSES),
        help="the mobility class every unit without its own (a team file's mobility:) names on its states; "
        "over terrain the planner plans it round that class's slope barriers (default: none, the planner's)",
    )
    p.add_argument("--speed-up", type=positive_float, default=1.0, help="simulated seconds per wall second")
    p.add_argument(
        "--duration-s",
        type=positive_float,
        metavar="S",
        help="stop after S simulated seconds (default: run on)",
    )
    p.add_argument(
        "--until-arrived", action="store_true", help="stop when every unit arrived (exit 1 if not)"
    )
    p.add_argument("--no-goals", action="store_true", help="do not put the team's goals")
    p.add_argument(
        "--reply-timeout-s", type=positive_float, default=1.0, help="wait this long for late answers"
    )
    p.add_argument(
        "--progress-s",
        type=positive_float,
        default=5.0,
        metavar="S",
        help="wall seconds between progress lines when stdout is not a terminal",
    )
    add_coords_arg(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_clients.fleet import FleetOptions, main
    from pfp_service.errors import InputError
    from pfp_service.team import generate_team, load_team
    from pfp_service.wire import GoalMobility

    for flag, value in (("--seed", args.seed), ("--area", args.area)):
        if args.team and value is not None:
            raise InputError(flag, "only goes with --generate (a team file gives its own units)")
    if args.team:
        team = load_team(args.team)
    else:
        team = generate_team(args.generate, 0 if args.seed is None else args.seed, args.area or 100.0)
    opts = FleetOptions(
        mission=args.mission,
        rate_hz=args.rate_hz,
        speed_up=args.speed_up,
        duration_s=args.duration_s,
        until_arrived=args.until_arrived,
        set_goals=not args.no_goals,
        reply_timeout_s=args.reply_timeout_s,
        coords=args.coords,
        gps_sigma_m=args.gps_sigma_m,
        stops=args.stops,
        mobility=None if args.mobility is None else GoalMobility(kind=args.mobility),
    )
    conf = session_config(args)
    with SignalStop() as stopping:  # 0 after SIGTERM, 130 after SIGINT, once the fleet has closed
        code = main(team, opts, conf, stopping.event, progress_s=args.progress_s)
    return stopping.exit_code(code)
