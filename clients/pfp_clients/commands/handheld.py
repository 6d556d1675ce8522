"""``pfp handheld``: the navigation client for a dismounted soldier (a terminal UI).

Shows the planner's direction as a big arrow with the compass bearing, the
distance and ETA to the goal, the threat level, the planner status and how
fresh the last update is.  The position comes from a simulated walk along the
directions, the arrow keys, or NMEA 0183 GGA sentences (``--nmea``).  With
the mission origin (``--origin``, or the planner's, learnt once connected)
positions show as lat/lon or MGRS (``--coords``), and a goal may be typed so.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from pfp_service.cli._common import add_session_args, positive_float, positive_int, session_config
from pfp_service.coords import STYLES, parse_point

__all__ = ["register", "run"]


def _pair(text: str, what: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return a, b


def point(text: str) -> tuple[float, float]:
    """``X,Y`` in metres."""
    return _pair(text, "X,Y in metres")


def lat_lon(text: str) -> tuple[float, float]:
    """``LAT,LON`` in decimal degrees."""
    return _pair(text, "LAT,LON in decimal degrees")


# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"handheld": "pfp handheld --unit m1 --goal 58,40"}


def register(sub: Any) -> None:
    p = sub.add_parser(
        "handheld", help="navigation client for a dismounted soldier (TUI)", description=__doc__
    )
    p.add_argument("--unit", required=True, metavar="ID", help="this unit's id")
    add_session_args(p)
    p.add_argument(
        "--goal",
        metavar="WHERE",
        help="ask the planner to guide this unit here: X,Y metres, 58.4105N 15.6213E or an MGRS reference "
        "(those two once the origin is known) (default: none; g sets one)",
    )
    p.add_argument(
        "--coords",
        choices=STYLES,
        help="how positions show: latlon or mgrs (with the mission origin), metres (default: latlon once "
        "an origin is known, else metres)",
    )
    p.add_argument("--start", type=point, default=(0.0, 0.0), metavar="X,Y", help="simulated start")
    p.add_argument("--speed-mps", type=positive_float, default=1.4, help="walking speed")
    p.add_argument(
        "--speed-up", type=positive_float, default=1.0, help="simulated walk runs this much faster"
    )
    p.add_argument("--no-walk", action="store_true", help="start with the simulated walk paused")
    p.add_argument("--nudge-m", type=positive_float, default=1.0, help="metres per arrow-key press")
    p.add_argument("--rate-hz", type=positive_float, default=2.0, help="state publish rate")
    p.add_argument("--stale-s", type=positive_float, default=5.0, help="flag updates older than this")
    p.add_argument("--threat-full-scale", type=positive_float, default=1.0, help="threat level of a full bar")
    g = p.add_argument_group("GPS")
    g.add_argument("--nmea", metavar="PATH|-", help="read GGA sentences from a file, serial device or stdin")
    g.add_argument("--nmea-baud", type=positive_int, metavar="BAUD", help="set a serial device's baud rate")
    g.add_argument(
        "--nmea-rate",
        type=positive_float,
        metavar="HZ",
        help="replay a file's GGA sentences at this rate (default: by their own UTC times)",
    )
    g.add_argument(
        "--origin",
        type=lat_lon,
        metavar="LAT,LON",
        help="the planner's (0, 0) as LAT,LON (needed with --nmea); checked against the planner's own origin once connected: when they differ no position is sent",
    )
    p.set_defaults(func=run)


def check_flags(args: argparse.Namespace) -> None:
    """Refuse flags that conflict or that nothing would use.

    Raises:
        InputError: naming the flag.
    """
    from pfp_service.errors import InputError

    if args.nmea is not None and args.origin is None:
        raise InputError("--origin", "required with --nmea (the LAT,LON of the planner's 0,0)")
    for flag, value in (
        ("--nmea-baud", args.nmea_baud),
        ("--nmea-rate", args.nmea_rate),
        ("--origin", args.origin),
    ):
        if args.nmea is None and value is not None:
            raise InputError(flag, "only goes with --nmea")
    if args.nmea is not None and args.no_walk:
        raise InputError("--no-walk", "the GPS gives the position: there is no simulated walk with --nmea")
    if args.goal is not None:
        origin = _origin(args)
        got = parse_point(args.goal, origin)
        if isinstance(got, str) and (origin is not None or "needs the mission origin" not in got):
            raise InputError("--goal", got)


def _origin(args: argparse.Namespace) -> Any:
    """The ``--origin`` as an ``Origin`` (``None`` without one)."""
    from pfp_service.geo import Origin

    return None if args.origin is None else Origin(lat=args.origin[0], lon=args.origin[1], alt=0.0)


def check_terminal(nmea: str | None) -> None:
    """A terminal UI needs a terminal: refuse a pipe or a file on stdout (or on stdin, unless ``--nmea -``).

    Raises:
        InputError: saying which side is not a terminal.
    """
    import os

    from pfp_service.errors import InputError

    if not os.isatty(1):
        raise InputError(
            "", "needs a terminal: stdout is not one (it is a terminal UI; run it in a terminal)"
        )
    if nmea != "-" and not os.isatty(0):
        raise InputError("", "needs a terminal: stdin is not one (pipe NMEA in with --nmea - instead)")


def run(args: argparse.Namespace) -> int:
    from pfp_service.cli._common import require_extra

    check_flags(args)
    require_extra("tui", "textual")
    session_config(args)  # a bad --zenoh-config or endpoint is a bad flag now, not a retry loop later
    check_terminal(args.nmea)

    import time

    from pfp_clients.handheld import HandheldApp
    from pfp_clients.handheld_link import RetryingLink
    from pfp_clients.handheld_model import HandheldModel, Settings
    from pfp_clients.nmea import LocalFrame
    from pfp_clients.nmea_feed import NmeaReader, open_nmea
    from pfp_service.node.config import DEFAULT_CONNECT
    from pfp_service.signals import SignalStop, leave_now

    gps = args.nmea is not None
    settings = Settings(
        unit=args.unit,
        speed_mps=args.speed_mps,
        speed_up=args.speed_up,
        walk=not gps and not args.no_walk,
        stale_after_s=args.stale_s,
        threat_full_scale=args.threat_full_scale,
        nudge_m=args.nudge_m,
        goal=metres if isinstance(metres := parse_point(args.goal or "", _origin(args)), tuple) else None,
        gps=gps,
    )
    frame = LocalFrame(*args.origin) if gps else None
    stream = open_nmea(args.nmea, args.nmea_baud) if gps else None
    where = ", ".join(args.connect or [DEFAULT_CONNECT])
    origin = frame.origin if frame is not None else None  # checked against the planner's once connected
    link = RetryingLink(lambda: session_config(args), where, args.mission, args.unit, origin=origin)
    with SignalStop() as stopping:  # 0 after SIGTERM, 130 after SIGINT, once the link has closed
        try:
            reader = None
            if stream is not None and frame is not None:
                reader = NmeaReader(stream, frame, link.inbox, rate_hz=args.nmea_rate)
            model = HandheldModel(settings, None if gps else args.start, time.monotonic())
            model.on_link(False, f"connecting to {where}")
            app = HandheldApp(
                model,
                link,
                mission=args.mission,
                source="nmea" if gps else "sim",
                nmea=reader,
                publish_hz=args.rate_hz,
                stopping=stopping,
                coords=args.coords,
                origin=origin,
                goal_text=args.goal if settings.goal is None else None,  # set once the origin is learnt
            )
            app.run()
            stopping.install()  # the app's closed loop put the default handlers back
            if reader is not None:
                reader.stop()
        finally:
            ended = link.close()
    code = stopping.exit_code(0)
    if not ended:  # its connecting thread is still inside zenoh.open: finalising under it aborts
        leave_now(code)
    return code
