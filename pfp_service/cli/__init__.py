"""The ``pfp`` command line: one subcommand per module.

Each command module defines ``register(subparsers)``, which adds its parser
and sets ``func(args) -> int``.  The commands of this package are found by
listing it, so a new command here is a new module and nothing else.  Other
packages add theirs through the ``pfp_service.commands`` entry-point group
(``pfp_clients`` adds fleet, inject, demo and handheld), so this package
never imports them: the dependency runs one way, clients -> service.

Help is plain text for a terminal, as httpie's is: doc markup (double
backticks) is dropped, paragraphs keep their breaks, indented lines are kept
as written, and every command ends with an example line.  A command module
gives its examples as ``EXAMPLES = {"plan": "pfp plan examples/geo-simple.yaml"}``
(one per command it registers); ``build_parser`` puts each under its parser.

Errors at this edge: an ``InputError`` (bad file, flag or value) prints one
line, ``pfp <command>: <field>: <reason>``, and exits 2, with no traceback;
so does a reader closing the pipe early (``pfp plan X | head -1``).
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import re
import sys
import textwrap
from collections.abc import Iterator, Sequence
from importlib.metadata import entry_points
from types import ModuleType
from typing import Any, NoReturn

from pfp_service import __version__
from pfp_service.errors import InputError

__all__ = ["COMMAND_GROUP", "ArgumentParser", "build_parser", "example_epilog", "main", "plain"]

COMMAND_GROUP = "pfp_service.commands"


_MARKUP = re.compile(r"``([^`]*)``|`([^`]*)`")
_NEW_PARAGRAPH = ("Exit codes", "Exit code")  # a paragraph of its own even when the docstring runs it on


def plain(text: str) -> str:
    """``text`` without doc markup: double (and single) backticks dropped (``--plot`` becomes --plot)."""
    return _MARKUP.sub(lambda m: m[1] if m[1] is not None else m[2], text)


class HelpFormatter(argparse.HelpFormatter):
    """Plain-text help: no doc markup, paragraphs and indented lines kept, and every flag's default shown
    in its help unless the help already says it."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        out: list[str] = []
        for para in re.split(r"\n\s*\n", plain(text).strip("\n")):
            lines = para.splitlines()
            block: list[str] = []  # running text, refilled; indented lines and bullets are kept as lines
            for line in [*lines, ""]:
                keep = line.startswith((" ", "\t")) or line.lstrip().startswith(("* ", "- "))
                if line.startswith(_NEW_PARAGRAPH) and block:
                    out.append(
                        textwrap.fill(" ".join(block), width, initial_indent=indent, subsequent_indent=indent)
                    )
                    out.append("")
                    block = []
                if (keep or not line) and block:
                    out.append(
                        textwrap.fill(" ".join(block), width, initial_indent=indent, subsequent_indent=indent)
                    )
                    block = []
                if keep:
                    bullet = line.lstrip().startswith(("* ", "- "))
                    hang = indent + "  " if bullet else indent + line[: len(line) - len(line.lstrip())]
                    out.append(
                        textwrap.fill(
                            line.strip(),
                            width,
                            initial_indent=hang[:-2] if bullet else hang,
                            subsequent_indent=hang,
                        )
                        if bullet
                        else indent + line.rstrip()
                    )
                elif line:
                    block.append(" ".join(line.split()))
            out.append("")
        return "\n".join(out).rstrip("\n")

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = plain(action.help or "")
        default = action.default
        if (
            "default" in text
            or default is None
            or default is False
            or default is argparse.SUPPRESS
            or not action.option_strings
        ):
            return text
        shown = ", ".join(map(str, default)) if isinstance(default, (list, tuple)) else default
        return f"{text} (default: {shown})"


# A word that starts with "-" and a digit (or "-." and a digit) is a value, never a flag: argparse's own
# pattern takes only plain numbers, so ``--origin -33.9,151.2`` or ``--goal -10,5`` were refused as
# "expected one argument".  No flag of ours starts with a digit, so nothing is shadowed.
NEGATIVE_VALUE = re.compile(r"^-\.?\d")


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2, help shows defaults, and a value
    may start with a minus sign (``--origin -33.9,-70.6``) in every command, as in every coordinate flag."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_VALUE

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def command_modules() -> Iterator[ModuleType]:
    """This package's command modules and those other packages registered, by command name.

    A name in this package wins over a registered one of the same name.
    """
    found = {ep.name: ep.value for ep in entry_points(group=COMMAND_GROUP)}
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            found[info.name] = f"{__name__}.{info.name}"
    for name in sorted(found):
        yield importlib.import_module(found[name])


def example_epilog(*lines: str) -> str:
    """The help's last paragraph: ``example:`` and each command line, indented (kept as written)."""
    return "example:\n" + "\n".join(f"  {line}" for line in lines)


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="pfp",
        description="Potential-field path planning for MUM-T teams.",
        epilog=example_epilog("pfp plan examples/geo-simple.yaml --plot geo.png", "pfp COMMAND --help"),
    )
    parser.add_argument("--version", action="version", version=f"pfp-service {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=ArgumentParser)
    for module in command_modules():
        register = getattr(module, "register", None)
        if register is None:
            continue
        register(sub)
    examples = _examples()
    for name, p in sub.choices.items():
        if p.epilog is None and name in examples:
            p.epilog = example_epilog(examples[name])
    return parser


def _examples() -> dict[str, str]:
    """Every loaded command module's ``EXAMPLES`` (a module's ``register`` may register another's
    commands, so they are gathered from all of them, not only the one registering)."""
    found: dict[str, str] = {}
    for module in list(sys.modules.values()):
        examples = getattr(module, "EXAMPLES", None)
        if isinstance(examples, dict) and callable(getattr(module, "register", None)):
            found.update(examples)
    return found


def _closed_pipe(command: str) -> int:
    # Python would print "Exception ignored ... BrokenPipeError" when it flushes stdout at exit
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    print(f"pfp {command}: stdout: the reader closed the pipe before the output was written", file=sys.stderr)
    return 2


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``pfp``'s command line (``argv``, else ``sys.argv``); the exit code.

    Run as the program (``argv`` is ``None``), it returns only once the threads
    Zenoh started for callbacks have ended; when one has not, the process
    ends here (``signals.settle_callback_threads``).
    """
    code = _run(argv)
    if argv is None:
        from pfp_service.signals import leave_now, settle_callback_threads

        if not settle_callback_threads():
            leave_now(code)
    return code


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    words = list(sys.argv[1:] if argv is None else argv)
    command = next((w for w in words if not w.startswith("-")), "")
    try:
        args = parser.parse_args(words)  # may print help: a closed pipe is possible from here on
        func = getattr(args, "func", None)
        if func is None:  # `pfp`, or `pfp bench` without a name: show what there is
            getattr(args, "help_parser", parser).print_help()
            sys.stdout.flush()
            return 0
        code = int(func(args))
        sys.stdout.flush()
        return code
    except InputError as exc:
        print(f"pfp {args.command}: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return _closed_pipe(command)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
