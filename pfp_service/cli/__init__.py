"""The ``pfp`` command line: one subcommand per module in this package.

Each module ``pfp_service.cli.<name>`` defines ``register(subparsers)``, which
adds its parser and sets ``func(args) -> int``.  This file finds them, so a new
command is a new module and nothing else.

Errors at this edge: an ``InputError`` (bad file, flag or value) prints one
line, ``pfp <command>: <field>: <reason>``, and exits 2, with no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence
from typing import NoReturn

from pfp_service import __version__
from pfp_service.errors import InputError

__all__ = ["ArgumentParser", "main"]


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog="pfp", description="Potential-field path planning for MUM-T teams.")
    parser.add_argument("--version", action="version", version=f"pfp-service {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=ArgumentParser)
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except InputError as exc:
        print(f"pfp {args.command}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
