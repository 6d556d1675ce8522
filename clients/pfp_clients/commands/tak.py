"""``pfp tak``: bridge a TAK network (ATAK, WinTAK, iTAK, a TAK server) and the planner, in Cursor-on-Target.

Hostile ground markers (``a-h-G*``) become threats (the uid is the id, the
time left to the marker's stale time its TTL, its course its facing, the
shape from the flags); a marker deleted in TAK removes its threat, and a TAK
server's replay of it does not bring it back before its stale time, even
after a restart (the tombstones are kept in --state-dir).  The planner's threats,
each unit (with its direction as course and its status) and each unit's
planned route go back to TAK.  Needs the ``[tak]`` extra (pytak) and the
mission origin, the same as ``pfp serve --origin``.

Exit codes: 0 stopped (SIGTERM); 2 a bad flag, or the extra is missing; 130 interrupted (SIGINT).
"""

from __future__ import annotations

import argparse
from typing import Any

from pfp_service.cli._common import add_session_args, non_negative_float, positive_float, positive_int

DEFAULT_COT_URL = "udp://239.2.3.1:6969"  # the TAK mesh's multicast group


def _origin(text: str) -> Any:
    from pfp_service.errors import InputError
    from pfp_service.geo import parse_origin

    try:
        return parse_origin(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None


def _cot_url(text: str) -> str:
    from urllib.parse import urlparse

    scheme = urlparse(text).scheme.lower().replace("+wo", "").replace("+ro", "")
    if scheme not in ("udp", "tcp", "tls", "ssl") or not urlparse(text).port:
        raise argparse.ArgumentTypeError(
            f"expected udp://, tcp:// or tls://HOST:PORT (+wo/+ro allowed), got {text!r}"
        )
    return text


# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"tak": "pfp tak --origin 58.4105,15.6213 --cot-url tcp://127.0.0.1:8087"}


def register(sub: Any) -> None:
    p = sub.add_parser("tak", help="bridge TAK (Cursor-on-Target) and the planner", description=__doc__)
    add_session_args(p)
    p.add_argument(
        "--origin", type=_origin, required=True, metavar="LAT,LON[,ALT]", help="the mission origin"
    )
    p.add_argument(
        "--cot-url",
        type=_cot_url,
        action="append",
        metavar="URL",
        help=f"TAK link, repeatable: udp://GROUP:PORT, tcp://HOST:PORT, tls://HOST:PORT (default: {DEFAULT_COT_URL})",
    )
    t = p.add_argument_group("TLS (tls:// links)")
    t.add_argument("--tls-cert", metavar="PEM", help="client certificate (default: none)")
    t.add_argument("--tls-key", metavar="PEM", help="client key (default: none)")
    t.add_argument("--tls-ca", metavar="PEM", help="CA that signed the server's certificate (default: none)")
    t.add_argument(
        "--tls-dont-verify", action="store_true", help="accept any server certificate (testing only)"
    )
    s = p.add_argument_group("threats from hostile markers (a marker carries only a position and a course)")
    s.add_argument(
        "--sigma-range", type=positive_float, default=50.0, metavar="M", help="spread along the facing, m"
    )
    s.add_argument("--sigma-lateral", type=positive_float, default=30.0, metavar="M", help="spread across, m")
    s.add_argument("--skew", type=non_negative_float, default=0.0, help="forward skew")
    s.add_argument("--weight", type=non_negative_float, default=1.0, help="threat weight")
    s.add_argument("--facing-deg", type=float, default=0.0, help="facing when the marker has no course")
    r = p.add_argument_group("outbound")
    r.add_argument(
        "--rate-s", type=positive_float, default=1.0, metavar="S", help="at most one event per uid per S"
    )
    r.add_argument(
        "--refresh-s", type=positive_float, default=30.0, metavar="S", help="re-send markers every S"
    )
    r.add_argument("--stale-s", type=positive_float, default=90.0, metavar="S", help="markers' stale time")
    r.add_argument(
        "--route-points", type=positive_int, default=50, metavar="N", help="waypoints per route, at most"
    )
    p.add_argument(
        "--terrain",
        metavar="DEM",
        help="a DEM (GeoTIFF, DTED, SRTM .hgt): routes' waypoints carry its ground height as hae, "
        "as the DEM gives it (no geoid applied; default: the origin's altitude)",
    )
    p.add_argument(
        "--state-dir",
        metavar="DIR",
        help="where deleted markers' tombstones outlive a restart; 'none' keeps them in memory only "
        "(default: $XDG_STATE_HOME/pfp/MISSION or ~/.local/state/pfp/MISSION)",
    )
    p.set_defaults(func=run)


def _terminated(_signum: int, _frame: Any) -> None:
    raise SystemExit(0)  # SIGTERM before the bridge's loop is up: a clean stop all the same


def run(args: argparse.Namespace) -> int:
    import logging
    import signal
    import sys

    from pfp_service.cli._common import require_extra, session_config
    from pfp_service.constraints import SIGMA_MIN_M, check_spreads
    from pfp_service.errors import InputError

    require_extra("tak", "pytak")
    from pfp_clients.tak import cot
    from pfp_clients.tak.bridge import TlsFiles
    from pfp_clients.tak.bridge import run as bridge
    from pfp_clients.tak.state import BridgeSettings

    for flag, v in (("--sigma-range", args.sigma_range), ("--sigma-lateral", args.sigma_lateral)):
        if v < SIGMA_MIN_M:
            raise InputError(flag, f"must be >= {SIGMA_MIN_M:g}")
    try:
        check_spreads(args.sigma_range, args.sigma_lateral)
    except ValueError as exc:
        raise InputError("--sigma-lateral", str(exc).split(": ", 1)[-1]) from None
    if args.route_points < 2:
        raise InputError("--route-points", "must be at least 2")
    ground = None
    if args.terrain is not None:
        require_extra("terrain", "rasterio")
        from pfp_clients.ground import load_ground

        ground = load_ground(args.terrain)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    for name in ("pytak", "pytak.classes"):  # pytak logs every worker start at INFO
        logging.getLogger(name).setLevel(logging.WARNING)
    settings = BridgeSettings(
        mission=args.mission,
        origin=args.origin,
        defaults=cot.ThreatDefaults(
            sigma_range_m=args.sigma_range,
            sigma_lateral_m=args.sigma_lateral,
            skew=args.skew,
            weight=args.weight,
            facing_deg=args.facing_deg % 360.0,
        ),
        rate_s=args.rate_s,
        refresh_s=args.refresh_s,
        stale_s=args.stale_s,
        route_points=args.route_points,
        ground=None if ground is None else ground.elevation,
    )
    tombstones = _tombstone_file(args)
    tls = TlsFiles(args.tls_cert, args.tls_key, args.tls_ca, args.tls_dont_verify)
    urls = args.cot_url or [DEFAULT_COT_URL]
    signal.signal(signal.SIGTERM, _terminated)
    print(f"pfp tak: mission {args.mission}, links {', '.join(urls)}", file=sys.stderr, flush=True)
    code = bridge(settings, urls, session_config(args), tls, tombstones=tombstones)
    print("pfp tak: stopped", file=sys.stderr, flush=True)
    return code


def _tombstone_file(args: argparse.Namespace) -> Any:
    import os
    from pathlib import Path

    from pfp_clients.tak.tombfile import FILE_NAME
    from pfp_service.errors import InputError
    from pfp_service.node.config import default_state_dir

    if args.state_dir == "none":
        return None
    folder = Path(args.state_dir) if args.state_dir else default_state_dir(os.environ, args.mission)
    if folder.exists() and not folder.is_dir():
        raise InputError("--state-dir", f"{folder} is not a directory")
    return folder / FILE_NAME
