"""``pfp handheld``: the navigation client for a dismounted soldier (a terminal UI).

Shows the planner's direction as a big arrow with the compass bearing, the
distance and ETA to the goal, the threat level, the planner status and how
fresh the last update is.  The position comes from a simulated walk along the
directions, the arrow keys, or NMEA 0183 GGA sentences (``--nmea``).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from pfp_service.cli._common import positive_float, positive_int

__all__ = ["register", "run"]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


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


def register(sub: Any) -> None:
    p = sub.add_parser(
        "handheld", help="navigation client for a dismounted soldier (TUI)", description=__doc__
    )
    p.add_argument("--unit", required=True, metavar="ID", help="this unit's id")
    p.add_argument("--mission", default="default")
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help=f"router to join (default {DEFAULT_ENDPOINT})"
    )
    p.add_argument("--goal", type=point, metavar="X,Y", help="ask the planner to guide this unit here")
    p.add_argument("--start", type=point, default=(0.0, 0.0), metavar="X,Y", help="simulated start")
    p.add_argument("--speed-mps", type=positive_float, default=1.4, help="walking speed (default 1.4)")
    p.add_argument(
        "--speed-up", type=positive_float, default=1.0, help="simulated walk runs this much faster"
    )
    p.add_argument("--no-walk", action="store_true", help="start with the simulated walk paused")
    p.add_argument("--nudge-m", type=positive_float, default=1.0, help="metres per arrow-key press")
    p.add_argument("--rate-hz", type=positive_float, default=2.0, help="state publish rate (default 2)")
    p.add_argument("--stale-s", type=positive_float, default=5.0, help="flag updates older than this")
    p.add_argument(
        "--threat-full-scale", type=positive_float, default=1.0, help="threat level of a full bar (default 1)"
    )
    p.add_argument("--nmea", metavar="PATH|-", help="read GGA sentences from a file, serial device or stdin")
    p.add_argument("--nmea-baud", type=positive_int, metavar="BAUD", help="set a serial device's baud rate")
    p.add_argument(
        "--origin", type=lat_lon, metavar="LAT,LON", help="local frame origin (needed with --nmea)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_service.errors import InputError

    if args.nmea is not None and args.origin is None:
        raise InputError("--origin", "required with --nmea (the LAT,LON of the planner's 0,0)")
    if args.nmea is None and args.nmea_baud is not None:
        raise InputError("--nmea-baud", "only makes sense with --nmea")

    import time

    from pfp_clients.handheld import HandheldApp
    from pfp_clients.handheld_link import NmeaReader, open_link, open_nmea
    from pfp_clients.handheld_model import HandheldModel, Settings
    from pfp_clients.nmea import LocalFrame

    gps = args.nmea is not None
    settings = Settings(
        unit=args.unit,
        speed_mps=args.speed_mps,
        speed_up=args.speed_up,
        walk=not gps and not args.no_walk,
        stale_after_s=args.stale_s,
        threat_full_scale=args.threat_full_scale,
        nudge_m=args.nudge_m,
        goal=args.goal,
    )
    frame = LocalFrame(*args.origin) if gps else None
    stream = open_nmea(args.nmea, args.nmea_baud) if gps else None
    with open_link(args.connect or [DEFAULT_ENDPOINT], args.mission, args.unit) as link:
        reader = NmeaReader(stream, frame, link.inbox) if stream is not None and frame is not None else None
        model = HandheldModel(settings, None if gps else args.start, time.monotonic())
        app = HandheldApp(
            model,
            link,
            mission=args.mission,
            source="nmea" if gps else "sim",
            nmea=reader,
            publish_hz=args.rate_hz,
        )
        app.run()
    return 0
