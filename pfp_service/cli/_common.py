"""What several subcommands share: argument types (``pfp_service.argtypes``), the Zenoh session flags, extras.

``add_session_args(parser)`` declares ``--connect``, ``--listen``, ``--mode``,
``--mission`` and ``--zenoh-config`` the same way for every command that opens
a session, and ``session_config(args)`` turns them into a ``zenoh.Config``.
``require_extra("tui", "textual")`` refuses to start a command whose optional
dependencies are missing, with the one ``pip install`` line that fixes it.
"""

from __future__ import annotations

import argparse
from typing import Any

from pfp_service.argtypes import (  # the commands take their flag types from here too
    MAX_CELLS,
    MIN_CELLS,
    bounded_int,
    grid_cells,
    non_negative_float,
    positive_float,
    positive_int,
)
from pfp_service.node.config import DEFAULT_CONNECT, DEFAULT_LISTEN

__all__ = [
    "MAX_CELLS",
    "MIN_CELLS",
    "MODES",
    "add_coords_arg",
    "add_session_args",
    "bounded_int",
    "grid_cells",
    "mission_chunk",
    "non_negative_float",
    "pip_hint",
    "positive_float",
    "positive_int",
    "require_extra",
    "session_config",
]

MODES = ("router", "peer", "client")


def mission_chunk(text: str) -> str:
    """``--mission``: one key chunk, 1-64 of ``[A-Za-z0-9_-]``."""
    from pfp_service.errors import InputError
    from pfp_service.wire import keys

    try:
        return keys.check_chunk(text, "--mission")
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None


def add_coords_arg(parser: argparse.ArgumentParser) -> None:
    """Declare ``--coords latlon|metres|mgrs``: how a command shows positions (``pfp_service.coords``)."""
    from pfp_service.coords import STYLES

    parser.add_argument(
        "--coords",
        choices=STYLES,
        help="how positions are shown: latlon (degrees, and metres from the origin), metres east and "
        "north of the origin, or mgrs grid references (default: latlon when the mission has an origin, "
        "else metres)",
    )


def add_session_args(parser: argparse.ArgumentParser, *, serve: bool = False) -> None:
    """Declare ``--connect``, ``--listen``, ``--mode`` and ``--mission`` on ``parser``.

    Args:
        serve: the planner's own flags: unset flags stay ``None`` so the config file
            and environment can supply them, and the help names the router defaults.
    """
    g = parser.add_argument_group("Zenoh session")
    if serve:
        g.add_argument("--mode", choices=MODES, help="Zenoh mode (default: router, an embedded router)")
        g.add_argument(
            "--listen",
            action="append",
            metavar="ENDPOINT",
            help=f"endpoint to listen on, repeatable (default for a router: {DEFAULT_LISTEN})",
        )
        g.add_argument(
            "--connect",
            action="append",
            metavar="ENDPOINT",
            help="router or peer to join, repeatable (default: none)",
        )
        g.add_argument(
            "--mission", type=mission_chunk, help="mission name, the {mission} key chunk (default: default)"
        )
        return
    g.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"router or peer to join, repeatable (default: {DEFAULT_CONNECT})",
    )
    g.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="endpoint to listen on too, repeatable (default: none)",
    )
    g.add_argument("--mode", choices=MODES, default="client", help="Zenoh mode")
    g.add_argument(
        "--mission", type=mission_chunk, default="default", help="mission name, the {mission} key chunk"
    )
    g.add_argument(
        "--zenoh-config",
        metavar="JSON5",
        help="Zenoh configuration to start from, e.g. a client file `pfp acl` wrote (its user and "
        "password); --mode, --listen and --connect override it (default: none)",
    )


def session_config(args: argparse.Namespace) -> Any:
    """The ``zenoh.Config`` of a client command's session flags (see ``add_session_args``).

    Raises:
        ZenohError: naming ``--zenoh-config`` (unreadable or invalid), ``--connect`` or ``--listen``.
    """
    from pfp_service.node.config import client_zenoh_config

    return client_zenoh_config(
        args.connect, mode=args.mode, listen=args.listen, file=getattr(args, "zenoh_config", None)
    )


def pip_hint(extra: str) -> str:
    """The command that installs ``extra`` into the Python running now, as a user would type it.

    The venv's own pip (``.venv/bin/pip`` when the venv is under the working
    directory), and ``-e 'DIR[extra]'`` for a source checkout, else the package
    from the index.
    """
    import sys
    from pathlib import Path

    def shown(path: Path) -> str:
        try:
            return str(path.relative_to(Path.cwd()))
        except ValueError:
            return str(path)

    python = Path(sys.executable)
    pip = python.with_name("pip")
    command = shown(pip) if pip.exists() else f"{shown(python)} -m pip"
    if pip.exists() and "/" not in command:  # a bare "pip" would be whatever pip the PATH finds first
        command = f"./{command}"
    source = Path(__file__).resolve().parents[2]
    if (source / "pyproject.toml").is_file():
        where = shown(source)
        target = f"-e '{'.' if where == '.' else where}[{extra}]'"
    else:
        target = f"'pfp-service[{extra}]'"
    return f"{command} install {target}"


def require_extra(extra: str, *modules: str) -> None:
    """Check that the modules an optional feature needs import, before the command starts.

    Raises:
        InputError: one line, ``needs the EXTRA extra: PIP install ...``, printed as
            ``pfp COMMAND: needs the tui extra: .venv/bin/pip install -e '.[tui]'`` (exit 2).
    """
    import importlib

    from pfp_service.errors import InputError

    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError:
            raise InputError("", f"needs the {extra} extra: {pip_hint(extra)}") from None
