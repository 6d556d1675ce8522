"""``pfp demo``: planner, a mixed fleet of six and a mid-route contingency, in one command (< 60 s)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import tempfile
from pathlib import Path
from typing import Any

from pfp_service.cli._common import positive_float
from pfp_service.errors import InputError

# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"demo": "pfp demo --out demo.png --quick"}


def register(sub: Any) -> None:
    p = sub.add_parser("demo", help="run the whole system once and plot it", description=__doc__)
    p.add_argument("--out", default="demo.png", metavar="PNG", help="where to write the plot (demo.png)")
    p.add_argument("--speed-up", type=positive_float, help="simulated seconds per wall second (default 5)")
    p.add_argument("--quick", action="store_true", help="shortened: run at x15 (used by the tests)")
    p.add_argument("--team", metavar="YAML", help="team file (default examples/demo-team.yaml)")
    p.add_argument("--script", metavar="YAML", help="injection script (default examples/demo-inject.yaml)")
    p.add_argument(
        "--map",
        nargs="?",
        const=0,
        type=int,
        metavar="PORT",
        help="serve the live map (the map extra) while the demo runs and print its URL; "
        "PORT on 127.0.0.1, a free one if left out (default: no map)",
    )
    p.add_argument(
        "--terrain",
        nargs="?",
        const="sample",
        metavar="DEM",
        help="the terrain variant (the terrain extra): tracked vehicles over real ground, threats masked by "
        "line of sight; without DEM, matplotlib's Jacksboro sample DEM (default team and script: "
        "examples/demo-terrain-team.yaml and demo-terrain-inject.yaml)",
    )
    p.add_argument(
        "--teams",
        action="store_true",
        help="the teaming variant: a scout leading the manned vehicle that controls it, and a wedge of robots, "
        "each team given one goal (examples/demo-teams-team.yaml and demo-teams-inject.yaml; docs/teams.md)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # a bad --team or --script file is one line and exit 2 before the imports of matplotlib and the
    # planner (1.3 s of CPU); the demo reads them again when it runs
    if args.team:
        from pfp_service.team import load_team

        load_team(Path(args.team))
    if args.script:
        from pfp_clients.script import load_script

        load_script(Path(args.script))
    from pfp_clients.demo import DemoOptions, run_demo
    from pfp_service.cli._common import require_extra

    require_extra("demo", "matplotlib")  # its plot: said before the demo runs, not after
    speed_up = args.speed_up or (15.0 if args.quick else 5.0)
    from pfp_service.render import check_png_path

    if args.map is not None and not 0 <= args.map <= 65535:
        raise InputError("--map", f"{args.map} is not a port (0-65535)")
    opts = DemoOptions(out=check_png_path(args.out, "--out"), speed_up=speed_up, map_port=args.map)
    if args.terrain is not None:
        require_extra("terrain", "rasterio")
        from pfp_clients.demo import DEMO_TERRAIN_SCRIPT, DEMO_TERRAIN_TEAM

        opts = dataclasses.replace(opts, team=DEMO_TERRAIN_TEAM, script=DEMO_TERRAIN_SCRIPT)
    if args.teams:
        from pfp_clients.demo import DEMO_TEAMS_SCRIPT, DEMO_TEAMS_TEAM

        opts = dataclasses.replace(opts, team=DEMO_TEAMS_TEAM, script=DEMO_TEAMS_SCRIPT)
    if args.team:
        opts = dataclasses.replace(opts, team=Path(args.team))
    if args.script:
        opts = dataclasses.replace(opts, script=Path(args.script))
    from pfp_service.signals import SignalStop

    with contextlib.ExitStack() as files:
        if args.terrain == "sample":  # the sample DEM, written where it is read and removed after
            from pfp_clients.sample_dem import write_jacksboro

            tmp = Path(files.enter_context(tempfile.TemporaryDirectory(prefix="pfp-demo-")))
            opts = dataclasses.replace(opts, terrain=write_jacksboro(tmp / "jacksboro.tif"))
        elif args.terrain is not None:
            opts = dataclasses.replace(opts, terrain=Path(args.terrain))
        with SignalStop() as stopping:  # 0 after SIGTERM, 130 after SIGINT, once the demo has closed
            code = run_demo(opts, lambda s: print(s, flush=True), stop=stopping.event)
        return stopping.exit_code(code)
