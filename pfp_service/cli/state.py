"""``pfp state list|clear``: show or remove a mission's durable state (threats, goals, missions).

The state lives where ``pfp serve`` keeps it: ``--state-dir``, else
``$XDG_STATE_HOME/pfp/MISSION`` (``~/.local/state/pfp/MISSION``), resolved
from the same flags, ``PFP_*`` variables and ``--config`` file as serve's.

``list`` without ``--mission`` shows every mission under the state home;
``clear`` removes one mission's state (``--mission``, default ``default``):
the database, its WAL, damaged files set aside, and the TAK bridge's
tombstones (``tak-tombstones.json``).  ``clear`` refuses, with
exit code 2 and nothing removed, while a planner runs on that state (it
holds ``state.lock``): stop the planner first.

Exit codes: 0 done (also when there was nothing to clear); 2 a bad flag, a
state dir that is off (``none``), or a planner running on the state.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from pfp_service.cli._common import mission_chunk

# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"state": "pfp state list"}


def register(sub: Any) -> None:
    p = sub.add_parser("state", help="show or remove a mission's durable state", description=__doc__)
    p.set_defaults(help_parser=p)  # `pfp state` alone shows the actions
    inner = p.add_subparsers(dest="action", metavar="ACTION", parser_class=type(p))
    ls = inner.add_parser("list", help="show missions' durable state: rows, size, damage, planner running")
    cl = inner.add_parser(
        "clear", help="remove one mission's durable state (refused while a planner runs on it)"
    )
    for q in (ls, cl):
        q.add_argument(
            "--mission",
            type=mission_chunk,
            help="the mission (default: every mission for list, 'default' for clear)",
        )
        q.add_argument("--state-dir", metavar="DIR", help="the state directory, as given to pfp serve")
        q.add_argument("--config", metavar="TOML", help="pfp serve's configuration file, for its state_dir")
    ls.add_argument("--json", action="store_true", help="print a JSON array, one object per mission")
    ls.set_defaults(func=run_list)
    cl.set_defaults(func=run_clear)


def _where(args: argparse.Namespace, mission: str | None) -> tuple[Path, bool]:
    """The state directory serve would use, and whether it was named (flag, env, file) or derived."""
    from pfp_service.errors import InputError
    from pfp_service.node.config import load_config

    flags = {"mission": mission, "state_dir": args.state_dir}
    cfg = load_config(args.config, os.environ, flags)
    if cfg.state_dir == "none":
        raise InputError("--state-dir", "durable state is off ('none'): there is nothing kept")
    named = args.state_dir is not None or "PFP_STATE_DIR" in os.environ
    if args.config is not None and not named:
        import tomllib

        from pfp_service.files import read_text

        named = "state_dir" in tomllib.loads(read_text(Path(args.config)))
    return Path(cfg.state_dir), named


def _row(mission: str, directory: Path) -> dict[str, Any]:
    from pfp_service.node.statefile import in_use, state_files

    sf = state_files(directory)
    return {
        "mission": mission,
        "path": str(directory),
        "threats": sf.counts.get("threats"),
        "goals": sf.counts.get("goals"),
        "missions": sf.counts.get("missions"),
        "rows_set_aside": sf.counts.get("set_aside", 0),
        "files_set_aside": [str(p) for p in sf.set_aside_files],
        "bytes": sf.bytes,
        "planner_running": in_use(directory),
        "error": sf.error,
    }


def run_list(args: argparse.Namespace) -> int:
    from pfp_service.node.config import default_state_dir
    from pfp_service.node.statefile import DB_NAME

    if args.mission is not None or args.state_dir is not None:
        directory, _named = _where(args, args.mission)
        rows = [_row(args.mission or directory.name, directory)] if (directory / DB_NAME).exists() else []
    else:
        directory, named = _where(args, None)
        if named:
            rows = [_row(directory.name, directory)] if (directory / DB_NAME).exists() else []
        else:  # every mission under the state home
            home = default_state_dir(os.environ, "default").parent
            found = sorted(d for d in home.iterdir() if (d / DB_NAME).exists()) if home.is_dir() else []
            rows = [_row(d.name, d) for d in found]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    if not rows:
        print(f"no durable state at {directory if args.mission or args.state_dir else directory.parent}")
        return 0
    print(
        f"{'MISSION':<16} {'THREATS':>7} {'GOALS':>7} {'MISSIONS':>8} {'SET ASIDE':>9} {'SIZE':>9}  PLANNER  PATH"
    )
    for r in rows:
        aside = r["rows_set_aside"] + len(r["files_set_aside"])
        print(
            f"{r['mission']:<16} {_n(r['threats']):>7} {_n(r['goals']):>7} {_n(r['missions']):>8} "
            f"{aside:>9} {_size(r['bytes']):>9}  {'running' if r['planner_running'] else '-':<7}  {r['path']}"
        )
        for f in r["files_set_aside"]:
            print(f"{'':<16} damaged file kept: {f}")
        if r["error"]:
            print(f"{'':<16} cannot read: {r['error']}")
    return 0


def run_clear(args: argparse.Namespace) -> int:
    from pfp_service.errors import InputError
    from pfp_service.node.statefile import clear

    mission = args.mission or "default"
    directory, _named = _where(args, args.mission)
    try:
        removed = clear(directory)
    except BlockingIOError:
        raise InputError(
            "--mission",
            f"{mission}: a planner is running on {directory}; stop it first (its state was left as it is)",
        ) from None
    except OSError as exc:
        raise InputError("--state-dir", f"{directory}: cannot clear: {exc}") from None
    if not removed:
        print(f"nothing to clear for mission {mission} ({directory})")
        return 0
    size = sum(n for _p, n in removed)
    print(f"cleared mission {mission}: {len(removed)} files, {_size(size)}, from {directory}")
    sys.stdout.flush()
    return 0


def _n(value: int | None) -> str:
    return "?" if value is None else str(value)


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB"):
        if n < 1024 or unit == "MiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024  # type: ignore[assignment]
    return f"{n} B"  # pragma: no cover
