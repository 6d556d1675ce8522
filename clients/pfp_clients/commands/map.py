"""``pfp map``: the operator's live map of a mission, served as one web page (a client, not the planner).

Registered under the ``pfp_service.commands`` entry-point group in pyproject.toml.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import sys
from typing import Any

from pfp_service.cli._common import add_session_args, positive_float, session_config
from pfp_service.signals import SignalStop

MAX_PUSH_HZ = 10.0


def http_address(text: str) -> tuple[str, int]:
    """``--http HOST:PORT`` (``[::1]:8080`` for IPv6; port 0 picks a free one)."""
    host, sep, port_text = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not sep or not host or not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, e.g. 127.0.0.1:8080, got {text!r}")
    return host, port


def origin(text: str) -> Any:
    """``--origin LAT,LON[,ALT]``: the mission origin, as ``pfp serve`` takes it."""
    from pfp_service.errors import InputError
    from pfp_service.geo import parse_origin

    try:
        return parse_origin(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None


def allowed_host(text: str) -> str:
    """``--allowed-host NAME``: a host name or IP address a browser may use for the map."""
    import ipaddress
    import re

    name = text.strip().lower().rstrip(".")
    bare = name[1:-1] if name.startswith("[") and name.endswith("]") else name
    try:
        ipaddress.ip_address(bare)
        return bare
    except ValueError:
        pass
    if not re.fullmatch(r"[a-z0-9_]([a-z0-9_-]*[a-z0-9_])?(\.[a-z0-9_]([a-z0-9_-]*[a-z0-9_])?)*", name):
        raise argparse.ArgumentTypeError(f"expected a host name or IP address, e.g. map.local, got {text!r}")
    return name


def height_m(text: str) -> float:
    from pfp_service.cli.terrain import height_m as metres

    return metres(text)


def push_rate(text: str) -> float:
    value = positive_float(text)
    if value > MAX_PUSH_HZ:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_PUSH_HZ:g}, got {text!r}")
    return value


# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"map": "pfp map --http 127.0.0.1:8080 --origin 58.4105,15.6213"}


def register(sub: Any) -> None:
    p = sub.add_parser("map", help="serve a live web map of the mission", description=__doc__)
    add_session_args(p)
    p.add_argument(
        "--http",
        type=http_address,
        default=("127.0.0.1", 8080),
        metavar="HOST:PORT",
        help="where to serve the page (default: 127.0.0.1:8080; port 0: any free port)",
    )
    p.add_argument("--allow-edit", action="store_true", help="let the page put and delete threats and goals")
    p.add_argument(
        "--allowed-host",
        type=allowed_host,
        action="append",
        metavar="NAME",
        help="a host name the page may be opened by besides the --http address, repeatable; any other "
        "Host header is refused (DNS rebinding) (default: the --http address, and localhost on loopback)",
    )
    p.add_argument(
        "--origin",
        type=origin,
        metavar="LAT,LON[,ALT]",
        help="the mission origin (the planner's (0, 0)): draw in lat/lon (default: the planner's, else plain metres)",
    )
    p.add_argument(
        "--tiles",
        metavar="URL",
        help="tile URL template of an offline tile server, e.g. http://tiles/{z}/{x}/{y}.png",
    )
    p.add_argument(
        "--terrain",
        metavar="DEM",
        help="a DEM (GeoTIFF, DTED, SRTM .hgt) to shade under the map, and to show a clicked threat's "
        "viewshed over (without an origin, the DEM's centre is the origin)",
    )
    p.add_argument(
        "--target-height",
        type=height_m,
        default=1.8,
        metavar="M",
        help="a threat's viewshed shows where a target this tall is seen (default 1.8: a soldier standing)",
    )
    p.add_argument(
        "--push-hz",
        type=push_rate,
        default=5.0,
        help=f"updates per second to the page, at most {MAX_PUSH_HZ:g}",
    )
    p.add_argument(
        "--stale-s", type=positive_float, default=10.0, help="draw a unit stale after this silence in s"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_clients.common import open_session
    from pfp_service.cli._common import require_extra
    from pfp_service.errors import InputError

    if args.tiles is not None and args.origin is None:
        raise InputError("--tiles", "tiles need --origin: without one the map is drawn in plain metres")
    require_extra("map", "aiohttp")
    ground = None
    if args.terrain is not None:  # refused (one line, exit 2) before any session opens
        require_extra("terrain", "rasterio")
        from pfp_clients.ground import load_ground

        ground = load_ground(args.terrain)
    from pfp_clients.map.server import MapOptions

    host, port = args.http
    opts = MapOptions(
        mission=args.mission,
        host=host,
        port=port,
        allow_edit=args.allow_edit,
        push_hz=args.push_hz,
        stale_s=args.stale_s,
        origin=args.origin,
        tiles=args.tiles,
        allowed_hosts=tuple(args.allowed_host or ()),
        terrain=ground,
        target_height_m=args.target_height,
    )
    conf = session_config(args)
    with SignalStop() as stopping, open_session(conf) as session:
        if opts.origin is None and not stopping.signalled:  # as pfp fleet does: the planner's, if it has one
            from pfp_clients.frames import planner_origin, shown

            answered, learned = planner_origin(session, opts.mission)
            if learned is not None:
                opts = dataclasses.replace(opts, origin=learned)
                print(f"pfp map: drawn in lat/lon from the planner's origin {shown(learned)}", flush=True)
            elif ground is not None:
                from pfp_clients.frames import shown

                centre = ground.centre()
                opts = dataclasses.replace(opts, origin=centre)
                print(f"pfp map: drawn in lat/lon from the DEM's centre {shown(centre)}", flush=True)
            elif not answered:
                print(
                    f"pfp map: no planner of mission {opts.mission!r} answered yet: drawn in plain metres "
                    "(give --origin, or start the map after pfp serve)",
                    flush=True,
                )
        elif (
            opts.origin is not None and not stopping.signalled
        ):  # drawn with another origin, all would be off
            from pfp_clients.frames import check_origin

            note = check_origin(session, opts.mission, opts.origin)
            if note is not None:
                print(f"pfp map: {note}", file=sys.stderr, flush=True)
        if stopping.signalled:  # while the session opened, or the origin was checked
            return stopping.exit_code(0)
        code = asyncio.run(_serve(session, opts, stopping))
        stopping.install()  # the closed loop put the default handlers back; the session closes next
    return stopping.exit_code(code)


async def _serve(session: Any, opts: Any, stopping: SignalStop) -> int:
    """``server.serve`` until SIGTERM or SIGINT, remembering which came (0 or 130 to exit with)."""
    from pfp_clients.map.server import serve
    from pfp_service.signals import SIGNALS

    stop = asyncio.Event()
    task = asyncio.create_task(serve(session, opts, stop=stop))
    # serve's first step installs its own handlers (stop.set, which cannot tell SIGTERM from SIGINT);
    # once it has run, ours replace them and note the signal as well
    await asyncio.sleep(0)

    def signalled(signum: int) -> None:
        stopping.note(signum)
        stop.set()

    loop = asyncio.get_running_loop()
    for sig in SIGNALS:
        loop.add_signal_handler(sig, signalled, sig)
    if stopping.signalled:  # came before the loop's handlers were in place
        stop.set()
    return await task
