"""``pfp bench NAME``: the project's benchmarks, one module each in ``pfp_service.bench``.

Each benchmark module defines ``add_arguments(parser)`` and ``run(args) -> int``
and a one-line module docstring used as its help.  Figures are compared as
ratios measured in the same run, because these machines are noisy.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from typing import Any

import pfp_service.bench as _bench_pkg
from pfp_service.cli import example_epilog

EXAMPLES = {"bench": "pfp bench engine --quick --check"}


def register(sub: Any) -> None:
    p = sub.add_parser("bench", help="run a benchmark (engine, quality, ...)", description=__doc__)
    names = sub_benchmarks()
    inner = p.add_subparsers(dest="benchmark", metavar="NAME", parser_class=type(p))
    p.set_defaults(help_parser=p)  # `pfp bench` alone lists the benchmarks
    for name in names:
        module = importlib.import_module(f"pfp_service.bench.{name}")
        if not (hasattr(module, "add_arguments") and hasattr(module, "run")):
            continue  # a helper module of the benchmarks (cases, baselines), not a benchmark
        doc = (module.__doc__ or name).strip().splitlines()[0]
        bp = inner.add_parser(name, help=doc, description=module.__doc__)
        module.add_arguments(bp)
        gates = any("--check" in a.option_strings for a in bp._actions)  # a benchmark with targets
        bp.epilog = example_epilog(f"pfp bench {name}" + (" --check" if gates else ""))
        bp.set_defaults(func=_runner(name))


def sub_benchmarks() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(_bench_pkg.__path__) if not m.name.startswith("_"))


def _runner(name: str) -> Any:
    def run(args: argparse.Namespace) -> int:
        module = importlib.import_module(f"pfp_service.bench.{name}")
        return int(module.run(args))

    return run
