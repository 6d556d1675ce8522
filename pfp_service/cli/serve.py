"""``pfp serve``: run the planner daemon on Zenoh (embedded router by default)."""

from __future__ import annotations

import argparse
import json
import os
from typing import Any

from pfp_service.cli._common import (
    add_coords_arg,
    add_session_args,
    bounded_int,
    non_negative_float,
    positive_float,
    positive_int,
)
from pfp_service.constraints import Delta, Step, Tolerance, flag_type
from pfp_service.core.options import ESCAPES


def _bounds(text: str) -> object:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        raise argparse.ArgumentTypeError("expected JSON like [[0, 0], [100, 100]]") from None


def _origin(text: str) -> object:
    import msgspec

    from pfp_service.errors import InputError
    from pfp_service.geo import parse_origin

    try:
        return msgspec.to_builtins(parse_origin(text))
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None


# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"serve": "pfp serve --origin 58.4105,15.6213 --mission exercise1"}


def register(sub: Any) -> None:
    p = sub.add_parser(
        "serve",
        help="run the planner daemon",
        description=__doc__ + " Precedence: defaults < --config TOML < PFP_* environment < flags.",
    )
    p.add_argument("--config", metavar="TOML", help="configuration file (default: none)")
    p.add_argument(
        "--zenoh-config", metavar="JSON5", help="Zenoh configuration file passed through (default: none)"
    )
    add_session_args(p, serve=True)
    p.add_argument("--planner-id", help="this planner's id (default: planner)")
    p.add_argument(
        "--log-format", choices=("human", "json"), help="log lines for people or JSON (default: human)"
    )
    p.add_argument("--log-level", choices=("debug", "info", "warning", "error"), help="(default: info)")
    add_coords_arg(p)
    g = p.add_argument_group("planner defaults (a goal message may override delta, step, tolerance)")
    # the bounds of a goal message's own delta, step and tolerance (constraints), for the same words
    g.add_argument(
        "--delta", type=flag_type(Delta, "a goal weight"), help="goal weight (default: the scale-free rule)"
    )
    g.add_argument(
        "--step",
        type=flag_type(Step, "a length in m"),
        help="step length in m (default: the scale-free rule)",
    )
    g.add_argument(
        "--tolerance",
        type=flag_type(Tolerance, "a length in m"),
        help="arrival tolerance in m (default: the scale-free rule)",
    )
    g.add_argument("--intensity", choices=("peak", "density"), help="threat intensity scale (default: peak)")
    g.add_argument("--escape", choices=ESCAPES, help="trap-escape strategy (default: auto)")
    w = p.add_argument_group("the live world")
    w.add_argument(
        "--threat-ttl-s", type=positive_float, help="TTL of threats that carry none (default: none)"
    )
    w.add_argument(
        "--unit-stale-s", type=positive_float, help="silence after which a unit is stale (default: 10)"
    )
    w.add_argument(
        "--liveliness-debounce-s",
        type=non_negative_float,
        help="how long a unit's token must stay gone before it is stale (default: 2)",
    )
    w.add_argument(
        "--preview-budget-ms", type=positive_float, help="time budget of one preview (default: 500)"
    )
    w.add_argument(
        "--team-preview-budget-ms",
        type=positive_float,
        help="time budget of one team preview (default: 5000)",
    )
    w.add_argument(
        "--preview-max-iter", type=positive_int, help="iteration cap of one preview (default: 200000)"
    )
    w.add_argument(
        "--lookahead", type=bounded_int(0, 100), help="predicted positions per direction, 0-100 (default: 5)"
    )
    w.add_argument(
        "--tick-s", type=positive_float, help="longest wait of the planning loop when idle (default: 0.05)"
    )
    w.add_argument(
        "--bounds",
        type=_bounds,
        metavar="JSON",
        help="mission bounds [[xmin,ymin],[xmax,ymax]] (default: none)",
    )
    w.add_argument(
        "--multicast", action="store_const", const=True, help="enable Zenoh multicast scouting (default: off)"
    )
    w.add_argument(
        "--unit-forget-s",
        type=positive_float,
        help="a unit stale this long is forgotten, with an event (default: 600)",
    )
    w.add_argument(
        "--max-units", type=bounded_int(1, 10_000_000), help="units held at most (default: 100000)"
    )
    w.add_argument(
        "--max-threats", type=bounded_int(1, 1_000_000), help="threats held at most (default: 10000)"
    )
    w.add_argument(
        "--zones",
        metavar="FILE.geojson",
        help="keep-out zones (RFC 7946 Polygons and MultiPolygons, lon/lat: needs --origin), put when the "
        "planner starts (default: none)",
    )
    d = p.add_argument_group("deliberation and previews, off the planning loop")
    d.add_argument(
        "--deliberation-workers",
        type=bounded_int(1, 64),
        help="worker processes for look-ahead and escape searches (default: 1)",
    )
    d.add_argument(
        "--deliberation-budget-s",
        type=positive_float,
        help="a deliberation not started within this is dropped; the unit descends (default: 5)",
    )
    d.add_argument(
        "--preview-workers", type=bounded_int(1, 64), help="worker processes answering previews (default: 2)"
    )
    d.add_argument(
        "--preview-queue",
        type=bounded_int(1, 100_000),
        help="previews in flight at most; more are refused as busy (default: 256)",
    )
    d.add_argument(
        "--preview-wait-ms",
        type=positive_float,
        help="a preview that cannot start within this is answered busy at once, with a retry hint "
        "(default: 2000)",
    )
    p.add_argument(
        "--cluster",
        action="store_const",
        const=True,
        help="share the mission with other planners started with --cluster: each guides the units "
        "rendezvous hashing gives it, and takes over a failed planner's units (default: off)",
    )
    p.add_argument(
        "--dispersion",
        action="store_const",
        const=True,
        help="keep friendly units apart (50 m between vehicles, 5 m on foot; per class and unit in the "
        "config file), with right of way and deadlocks broken (default: off)",
    )
    p.add_argument(
        "--state-dir",
        metavar="DIR",
        help="durable state (threats, goals, missions) in SQLite; 'none' turns it off "
        "(default: $XDG_STATE_HOME/pfp/MISSION or ~/.local/state/pfp/MISSION)",
    )
    p.add_argument(
        "--origin",
        type=_origin,
        metavar="LAT,LON[,ALT]",
        help="mission origin in WGS-84 degrees (and metres): [0, 0] lies there and positions may be "
        "{lat, lon} (default: none)",
    )
    p.add_argument(
        "--terrain",
        metavar="DEM",
        help="plan over this DEM (GeoTIFF, DTED, SRTM .hgt; terrain extra), loaded once: threats masked "
        "by line of sight, ground steeper than --terrain-unit's limit a barrier; with no --origin the "
        "DEM's centre is the origin (default: none)",
    )
    p.add_argument(
        "--terrain-unit",
        choices=("foot", "wheeled", "tracked"),
        help="the mobility class planned for over --terrain: its height and slope limit (default: foot)",
    )
    p.add_argument(
        "--sight-wait-s",
        type=positive_float,
        help="over --terrain, how long a threat put waits for its window of sight before it takes force "
        "blind, seeing through the ground, until the window lands (default: 0.25)",
    )
    p.set_defaults(func=run)


_FLAG_KEYS = [
    "mode",
    "listen",
    "connect",
    "mission",
    "planner_id",
    "log_format",
    "log_level",
    "coords",
    "delta",
    "step",
    "tolerance",
    "intensity",
    "escape",
    "threat_ttl_s",
    "unit_stale_s",
    "liveliness_debounce_s",
    "preview_budget_ms",
    "team_preview_budget_ms",
    "preview_max_iter",
    "lookahead",
    "tick_s",
    "bounds",
    "origin",
    "multicast",
    "zenoh_config",
    "unit_forget_s",
    "max_units",
    "max_threats",
    "zones",
    "deliberation_workers",
    "deliberation_budget_s",
    "preview_workers",
    "preview_queue",
    "preview_wait_ms",
    "state_dir",
    "cluster",
    "terrain",
    "terrain_unit",
    "sight_wait_s",
    "dispersion",
]


def run(args: argparse.Namespace) -> int:
    from pfp_service.node.config import load_config
    from pfp_service.node.run import serve

    flags = {k: getattr(args, k) for k in _FLAG_KEYS}
    cfg = load_config(args.config, os.environ, flags)
    if cfg.terrain is not None:  # a bad DEM is one line and exit 2, before anything starts
        from pfp_service.node.terrain import placed

        cfg = placed(cfg)
    if cfg.zones is not None:  # a bad zones file is one line and exit 2, before anything starts
        from pfp_service.geojson import load_zones

        load_zones(cfg.zones, cfg.origin)
    return serve(cfg)
