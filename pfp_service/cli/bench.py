"""``pfp bench NAME``: the project's benchmarks, one module each in the top-level ``benchmarks`` package.

Each benchmark module defines ``add_arguments(parser)`` and ``run(args) -> int``
and a one-line module docstring used as its help.  Figures are compared as
ratios measured in the same run, because these machines are noisy.

The benchmarks live beside this package in a source checkout, not inside it, so an
installed wheel does not ship them (as msgspec keeps ``benchmarks/`` outside its
source).  ``pfp bench`` finds them next to ``pfp_service`` (an editable install or a
checkout on the path); without them it says so in one line and exits 2.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import pkgutil
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pfp_service
from pfp_service.cli import example_epilog
from pfp_service.errors import InputError

EXAMPLES = {"bench": "pfp bench engine --quick --check"}

PACKAGE = "benchmarks"
NO_CHECKOUT = (
    "the benchmarks need a source checkout (an editable install: pip install -e .), which this install is not"
)


def benchmarks_package() -> ModuleType | None:
    """The ``benchmarks`` package of this checkout: already imported, or loaded from beside ``pfp_service``.

    Loaded by its path, never by putting the checkout on ``sys.path``, so nothing else of the
    checkout (tests, clients) becomes importable by the way.  ``None`` for an installed wheel.
    """
    if PACKAGE in sys.modules:
        return sys.modules[PACKAGE]
    init = Path(pfp_service.__file__).resolve().parent.parent / PACKAGE / "__init__.py"
    if not init.is_file():
        return None
    spec = importlib.util.spec_from_file_location(
        PACKAGE, init, submodule_search_locations=[str(init.parent)]
    )
    if spec is None or spec.loader is None:
        return None
    module = importlib.util.module_from_spec(spec)
    sys.modules[PACKAGE] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[PACKAGE]
        raise
    return module


def register(sub: Any) -> None:
    p = sub.add_parser("bench", help="run a benchmark (engine, quality, ...)", description=__doc__)
    package = benchmarks_package()
    if package is None:  # an installed wheel: every `pfp bench ...` is the one line
        p.add_argument("name", nargs="?", help=argparse.SUPPRESS)
        p.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
        p.set_defaults(func=_no_checkout)
        return
    inner = p.add_subparsers(dest="benchmark", metavar="NAME", parser_class=type(p))
    p.set_defaults(help_parser=p)  # `pfp bench` alone lists the benchmarks
    for name in sub_benchmarks(package):
        module = importlib.import_module(f"{PACKAGE}.{name}")
        if not (hasattr(module, "add_arguments") and hasattr(module, "run")):
            continue  # a program of its own (recorder), run with python -m, not a benchmark
        doc = (module.__doc__ or name).strip().splitlines()[0]
        bp = inner.add_parser(name, help=doc, description=module.__doc__)
        module.add_arguments(bp)
        gates = any("--check" in a.option_strings for a in bp._actions)  # a benchmark with targets
        bp.epilog = example_epilog(f"pfp bench {name}" + (" --check" if gates else ""))
        bp.set_defaults(func=_runner(name))


def sub_benchmarks(package: ModuleType) -> list[str]:
    """The package's modules but its helpers (``_cases``): a helper is never imported to build the parser."""
    return sorted(m.name for m in pkgutil.iter_modules(package.__path__) if not m.name.startswith("_"))


def _no_checkout(args: argparse.Namespace) -> int:
    raise InputError("", NO_CHECKOUT)


def _runner(name: str) -> Any:
    def run(args: argparse.Namespace) -> int:
        module = importlib.import_module(f"{PACKAGE}.{name}")
        return int(module.run(args))

    return run
