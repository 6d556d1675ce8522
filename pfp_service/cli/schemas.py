"""``pfp schemas``: regenerate ``schemas/`` (JSON Schema + examples), or ``--check`` it is current."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"schemas": "pfp schemas --check"}


def register(sub: Any) -> None:
    p = sub.add_parser("schemas", help="write or check the wire contract's JSON Schemas", description=__doc__)
    p.add_argument(
        "--check",
        action="store_true",
        help="change nothing; exit 1 and list what is stale if schemas/ is out of date",
    )
    p.add_argument(
        "--dir", default="schemas", metavar="DIR", help="the schemas directory (default: ./schemas)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_service.errors import InputError
    from pfp_service.wire import schema
    from pfp_service.world import translate

    directory = Path(args.dir)
    if directory.exists() and not directory.is_dir():
        raise InputError(str(directory), "is not a directory")
    files = schema.render(translate.supplied())
    if args.check:
        try:
            stale = schema.diff(directory, files)
        except OSError as exc:
            raise InputError(str(directory), f"cannot read: {exc.strerror or exc}") from exc
        for line in stale:
            print(f"pfp schemas: {directory}: {line}", file=sys.stderr)
        if stale:
            print("pfp schemas: stale; run `pfp schemas` and commit the result", file=sys.stderr)
            return 1
        print(f"{directory}: up to date")
        return 0
    try:
        changes = schema.write(directory, files, log=lambda line: print(f"{directory}: {line}"))
    except OSError as exc:
        raise InputError(str(directory), f"cannot write: {exc.strerror or exc}") from exc
    if not changes:
        print(f"{directory}: up to date")
    return 0
